# talus: two commands do everything on a fresh machine (README.md).
#   make demo   set up, then run the main job on the digital twin
#   make test   set up, then run the whole test suite
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
# Debian packages the project needs at run or test time. postgresql: the clinical record's
# tests start a throw-away server (tests/pg_server.py); poppler-utils (pdftoppm, pdftotext,
# pdffonts) checks the PDF reports in the tests; Xvfb and the xcb libraries: a real Qt window
# for the GUI smoke test (PLATFORM.md).
APT_PACKAGES := postgresql poppler-utils xvfb xauth libxcb-icccm4 libxcb-keysyms1 \
  libxcb-xinerama0 libegl1 libgl1 libxkbcommon-x11-0 libxcb-cursor0 libxcb-shape0 \
  libxcb-randr0 libxcb-render-util0 libxcb-image0 libfontconfig1 libdbus-1-3

.PHONY: demo test setup system-deps bench clean translations

setup: system-deps $(STAMP)

system-deps:
	@if [ -n "$(APT_PACKAGES)" ]; then \
	  missing=$$(for p in $(APT_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	  if [ -n "$$missing" ]; then \
	    echo "installing Debian packages: $$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; \
	  fi; \
	fi

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

demo: setup
	$(BIN)/talus model demo
	@echo
	$(BIN)/talus bench tracking --experiment parameter-step --rate 100
	@echo
	@mkdir -p out
	$(BIN)/talus db demo --db out/demo.db
	@echo
	export TALUS_PASSWORD="$${TALUS_PASSWORD:-$$($(BIN)/python -c 'import json; \
	  print(json.load(open("out/talus-demo-credentials.json"))["password"])')}"; \
	for p in sine_fz gait_replay; do \
	  $(BIN)/talus session run --protocol protocols/library/$$p.yaml --record-dir out \
	    --db out/demo.db --user demo-clinician --patient DEMO-001 || exit 1; echo; \
	done; \
	$(BIN)/talus sessions list --patient DEMO-001 --db out/demo.db --user demo-clinician; \
	echo; \
	for uid in $$($(BIN)/talus sessions list --patient DEMO-001 --db out/demo.db \
	    --user demo-clinician --json | $(BIN)/python -c 'import json, sys; \
	    print(" ".join(s["uid"] for s in json.load(sys.stdin)[-2:]))'); do \
	  $(BIN)/talus report session --session $$uid --db out/demo.db --user demo-clinician \
	    --out out/session_$$uid.pdf --force || exit 1; \
	done; \
	$(BIN)/talus report progress --patient DEMO-001 --db out/demo.db --user demo-clinician \
	  --out out/progress_DEMO-001.pdf --force
# PDF reports above: the two demo sessions and DEMO-001's progress from the clinical record;
# below, an example history's progress and a certificate from an example calibration record.
	$(BIN)/talus report progress --input reports/data/demo_progress.json \
	  --out out/progress_twin-demo.pdf --force
	$(BIN)/talus report calibration --record reports/data/example_calibration_record.json \
	  --out out/calibration_example.pdf --force
	@echo
	@# out/calibration is this target's own output (a campaign folder must be new).
	rm -rf out/calibration
	$(BIN)/talus calibrate demo --out out/calibration

# Static checks first (each fails the target): ruff over the code and its tests, mypy over
# the packages listed in pyproject.toml's [tool.mypy].
LINT_PATHS := talus rt protocols patients calibration reports app tests bench

test: setup
	$(BIN)/ruff check $(LINT_PATHS)
	$(BIN)/mypy
	$(BIN)/pytest -q

# The GUI's Spanish: extract new strings into the .ts (translated with pyside6-linguist or by
# hand), then compile the .qm the app loads (both are committed).
translations: setup
	$(BIN)/pyside6-lupdate app/*.py app/pages/*.py -ts app/i18n/talus_es.ts -no-obsolete
	$(BIN)/pyside6-lrelease app/i18n/talus_es.ts -qm app/i18n/talus_es.qm

bench: setup
	$(BIN)/python bench/model.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis
