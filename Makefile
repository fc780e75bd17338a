# talus: two commands do everything on a fresh machine (README.md).
#   make demo   set up, then run the main job on the digital twin
#   make test   set up, then run the whole test suite
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
# Debian packages the project needs at run or test time: poppler-utils (pdftoppm, pdftotext,
# pdffonts) checks the PDF reports in the tests.
APT_PACKAGES := poppler-utils

.PHONY: demo test setup system-deps bench clean

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
	$(BIN)/talus bench tracking --experiment payload-step
	@echo
	@mkdir -p out
	$(BIN)/talus session run --protocol protocols/library/sine_fz.yaml --record out/sine_fz.mcap
	@echo
	$(BIN)/talus session run --protocol protocols/library/gait_replay.yaml --patient-weight 75 \
	  --record out/gait_replay.mcap
	@echo
# PDF reports: one per demo session, the demo patient's progress (an example history),
# and a certificate from an example calibration record.
	$(BIN)/talus report session --recording out/sine_fz.mcap --out out/sine_fz.pdf --force
	$(BIN)/talus report session --recording out/gait_replay.mcap --out out/gait_replay.pdf --force
	$(BIN)/talus report progress --input reports/data/demo_progress.json \
	  --out out/progress_twin-demo.pdf --force
	$(BIN)/talus report calibration --record reports/data/example_calibration_record.json \
	  --out out/calibration_example.pdf --force

test: setup
	$(BIN)/pytest -q

bench: setup
	$(BIN)/python bench/model.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis
