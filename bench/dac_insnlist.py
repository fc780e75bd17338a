"""The rig's DAC write through ctypes: three ``comedi_data_write`` calls against one
``comedi_do_insnlist`` (issue 16), with C stubs in place of comedilib (no card here): what the
Python side of the cycle pays to cross into C. On the rig each comedilib call is also one
ioctl into the comedi driver, so the list saves two system calls more, which this machine
cannot measure. Also the twin's write on the comedilib double, compiled and interpreted.
Prints median / p99 (µs) per way. Needs a C compiler.

    .venv/bin/python bench/dac_insnlist.py [--calls 20000]
"""
from __future__ import annotations

import argparse
import ctypes
import shutil
import subprocess
import tempfile
from pathlib import Path

import cycle_kernels
import numpy as np

from rt.drivers.fake_comedi import FakeComedi
from rt.drivers.pci1720 import Pci1720Outputs, comedilib_prototypes

_STUB = r"""
struct comedi_insnlist;
unsigned int last[4];
int comedi_data_write(void *dev, unsigned sub, unsigned chan, unsigned rng, unsigned aref,
                      unsigned data) { last[chan & 3] = data; return 1; }
int comedi_do_insnlist(void *dev, struct comedi_insnlist *list) { return 3; }
"""


def _time(fn, calls: int) -> tuple[float, float]:
    # cycle_kernels' timer (this directory is on sys.path when a bench runs), with the 500
    # warm-up calls this bench has always made.
    return cycle_kernels._time(fn, calls, warm=500)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--calls", type=int, default=20000)
    args = p.parse_args(argv)
    if shutil.which("cc") is None:
        print("no C compiler: nothing measured")
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "stub.c"
        src.write_text(_STUB)
        so = Path(tmp) / "libstub.so"
        subprocess.run(["cc", "-O2", "-shared", "-fPIC", "-o", str(so), str(src)], check=True)
        c = ctypes.CDLL(str(so))
        protos = comedilib_prototypes()
        for name in ("comedi_data_write", "comedi_do_insnlist"):
            fn = getattr(c, name)
            fn.restype, fn.argtypes = protos[name]

        dev = ctypes.c_void_p(0x1000)
        write, insnlist = c.comedi_data_write, c.comedi_do_insnlist

        class _Lib(FakeComedi):
            """The double for the set-up calls; the cycle's list goes to the C stub."""

            def comedi_do_insnlist(self, handle, lst) -> int:
                return insnlist(dev, lst)

        dac = Pci1720Outputs(lib=_Lib())
        dac.enable()
        ptr = dac._insnlist_ptr
        codes = (2252, 1536, 3276)

        def three() -> None:
            write(dev, 0, 0, 3, 0, codes[0])
            write(dev, 0, 1, 3, 0, codes[1])
            write(dev, 0, 2, 3, 0, codes[2])

        def one() -> None:
            insnlist(dev, ptr)

        rows = [("3 x comedi_data_write", *_time(three, args.calls)),
                ("1 x comedi_do_insnlist", *_time(one, args.calls))]
        # The driver's whole compiled write with the list going to C (one Python frame more
        # than the rig, where ``comedi_do_insnlist`` is the ctypes function itself).
        volts = np.array([1.2, -0.4, 5.9])
        volts.flags.writeable = False
        rows.append(("write_volts (kernel + list)", *_time(lambda: dac.write_volts(volts),
                                                           args.calls)))
        # The twin's card: the comedilib double, compiled (codes and list in one call) and
        # with its interpreted reference in place of the compiled list (as the double was).
        twin_dac = Pci1720Outputs(lib=FakeComedi(keep_log=False))
        twin_dac.enable()

        class _Interpreted(FakeComedi):
            comedi_do_insnlist = FakeComedi.comedi_do_insnlist_interpreted

        ref_dac = Pci1720Outputs(lib=_Interpreted(keep_log=False))
        ref_dac.enable()
        rows.append(("twin: write_volts, compiled", *_time(lambda: twin_dac.write_volts(volts),
                                                           args.calls)))
        rows.append(("twin: write_volts, interpreted", *_time(
            lambda: ref_dac.write_volts(volts), args.calls)))
    print(f"{'call':30s} {'median µs':>10s} {'p99 µs':>10s}")
    for name, med, p99 in rows:
        print(f"{name:30s} {med:10.2f} {p99:10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
