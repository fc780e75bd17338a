"""What a Net F/T tells a client about its scaling: the ``netftapi2.xml`` page and the TCP
calibration-information command. Pure codecs, no sockets (``rt.ati.config_server`` serves them).

Clients that read their counts-per-unit from the sensor instead of assuming 1e6 (``pynetft``
2.x reads ``http://SENSOR:http_port/netftapi2.xml`` before it streams) need these to work
against the twin.

Facts (ATI Net F/T manual 9620-05-Net FT, "netftapi2.xml" and "TCP interface"):

* ``/netftapi2.xml`` is an XML document rooted at ``<netft>``; the fields clients read are
  ``cfgcpf`` (counts per force unit), ``cfgcpt`` (counts per torque unit), ``scfgfu`` /
  ``scfgtu`` (the force and torque unit names) and ``prodname``. The device serves many more
  fields (serial number, firmware, filter settings); talus serves these five, each once, text
  only, which is what ``pynetft`` 2.1 requires (checked in ``tests/test_ati_netft_config.py``
  against the real package).
* TCP port 49151 accepts a 20-byte command; command byte 0x01 (READCALINFO, the other 19 bytes
  reserved, zero) is answered with 24 bytes, big-endian: ``uint16 header = 0x1234``,
  ``uint8 force_units``, ``uint8 torque_units``, ``uint32 counts_per_force``,
  ``uint32 counts_per_torque``, ``uint16 scale_factors[6]`` (analog output scaling).
  Unit codes: force 1 lbf, 2 N, 3 klbf, 4 kN, 5 kgf, 6 gf; torque 1 lbf-in, 2 lbf-ft, 3 N-m,
  4 N-mm, 5 kgf-cm, 6 kN-m. **Not verified against a device** (written from the manual's C
  structures); the twin's own client decodes exactly this layout.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum
from xml.sax.saxutils import escape

from rt.ati.rdt import DEFAULT_COUNTS_PER_FORCE, DEFAULT_COUNTS_PER_TORQUE, RDT_HEADER
from rt.errors import InputError, ProtocolError

#: The sensor's HTTP page with its configuration.
NETFT_XML_PATH = "/netftapi2.xml"
#: TCP port of the Net F/T's command interface.
TCP_CALIBRATION_PORT = 49151
#: The TCP command asking for the calibration information.
CMD_READ_CAL_INFO = 0x01
CAL_INFO_REQUEST = struct.Struct(">B19x")
CAL_INFO_RESPONSE = struct.Struct(">HBBII6H")


class ForceUnit(IntEnum):
    """Force unit codes of the TCP interface; ``.label`` is the XML/display name."""

    LBF = 1
    N = 2
    KLBF = 3
    KN = 4
    KGF = 5
    GF = 6

    @property
    def label(self) -> str:
        return {1: "lbf", 2: "N", 3: "klbf", 4: "kN", 5: "kgf", 6: "gf"}[self.value]


class TorqueUnit(IntEnum):
    """Torque unit codes of the TCP interface; ``.label`` is the XML/display name."""

    LBF_IN = 1
    LBF_FT = 2
    N_M = 3
    N_MM = 4
    KGF_CM = 5
    KN_M = 6

    @property
    def label(self) -> str:
        return {1: "lbf-in", 2: "lbf-ft", 3: "N-m", 4: "N-mm", 5: "kgf-cm",
                6: "kN-m"}[self.value]


@dataclass(frozen=True)
class NetFtConfiguration:
    """The scaling a Net F/T reports. talus's twin works in N and N m."""

    counts_per_force: float = DEFAULT_COUNTS_PER_FORCE
    counts_per_torque: float = DEFAULT_COUNTS_PER_TORQUE
    force_unit: ForceUnit = ForceUnit.N
    torque_unit: TorqueUnit = TorqueUnit.N_M
    product_name: str = "talus twin Net F/T"
    #: Analog-output scale factors of the TCP answer (no analog output on the twin).
    scale_factors: tuple[int, int, int, int, int, int] = (1, 1, 1, 1, 1, 1)

    def __post_init__(self) -> None:
        for name in ("counts_per_force", "counts_per_torque"):
            value = getattr(self, name)
            # The TCP answer carries them as uint32: whole positive numbers below 2**32.
            if not (math.isfinite(value) and 1 <= value < 2**32 and value == int(value)):
                raise InputError(f"{name} must be a whole number in [1, 2**32), got {value}")

    def to_xml(self) -> bytes:
        """The ``netftapi2.xml`` document (ASCII)."""
        fields = (("prodname", escape(self.product_name)),
                  ("cfgcpf", str(int(self.counts_per_force))),
                  ("cfgcpt", str(int(self.counts_per_torque))),
                  ("scfgfu", self.force_unit.label),
                  ("scfgtu", self.torque_unit.label))
        body = "".join(f"<{tag}>{text}</{tag}>" for tag, text in fields)
        return f'<?xml version="1.0"?>\n<netft>{body}</netft>\n'.encode("ascii", "replace")

    def cal_info_response(self) -> bytes:
        """The 24-byte answer to READCALINFO."""
        return CAL_INFO_RESPONSE.pack(RDT_HEADER, self.force_unit, self.torque_unit,
                                      int(self.counts_per_force), int(self.counts_per_torque),
                                      *self.scale_factors)


def decode_cal_info_request(data: bytes) -> int:
    """The command byte of a 20-byte TCP request; ProtocolError for a wrong length."""
    if len(data) != CAL_INFO_REQUEST.size:
        raise ProtocolError(f"TCP command must be {CAL_INFO_REQUEST.size} bytes, "
                            f"got {len(data)}")
    return int(CAL_INFO_REQUEST.unpack(data)[0])


def decode_cal_info_response(data: bytes) -> NetFtConfiguration:
    """A READCALINFO answer as a configuration (client side); ProtocolError when malformed."""
    if len(data) != CAL_INFO_RESPONSE.size:
        raise ProtocolError(f"calibration answer must be {CAL_INFO_RESPONSE.size} bytes, "
                            f"got {len(data)}")
    header, fu, tu, cpf, cpt, *scale = CAL_INFO_RESPONSE.unpack(data)
    if header != RDT_HEADER:
        raise ProtocolError(f"calibration answer header is {header:#06x}, expected "
                            f"{RDT_HEADER:#06x}")
    try:
        force_unit, torque_unit = ForceUnit(fu), TorqueUnit(tu)
    except ValueError:
        raise ProtocolError(f"calibration answer has unknown unit codes {fu}, {tu}") from None
    try:
        return NetFtConfiguration(cpf, cpt, force_unit, torque_unit,
                                  scale_factors=tuple(scale))
    except InputError as exc:
        raise ProtocolError(f"calibration answer: {exc}") from None
