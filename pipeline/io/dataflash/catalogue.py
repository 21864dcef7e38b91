"""The one DataFlash message catalogue shared by every DataFlash writer.

A DataFlash log declares each message type in-band (``FMT``: type id, name, format characters,
field labels; modern logs add ``FMTU`` with unit and multiplier ids resolved through ``UNIT``
and ``MULT`` records). This module holds those declarations as data, so
:class:`pipeline.io.dataflash.writer.DataFlashWriter` users name a *layout* instead of spelling
definitions out:

``ardupilot4``
    Modern ArduPilot (copied from ArduPlane 4.2 ``pilot_0004.BIN``, instance fields ``I``):
    what the simulator's ``.bin`` files use (:func:`pipeline.io.dataflash.writer.write_bin`),
    plus the simulation radar :data:`RADR`.
``demo``
    The compact single-instance layout of the < 1 MB demo flight
    (:func:`pipeline.simulate.demo.write_demo_flight`; older ArduCopter field sets).

:data:`MESSAGES` is the table: one :class:`MessageDef` per (layout, message), in the order a
writer declares them (that order is part of the bytes written, so it is kept). :data:`UNITS` and
:data:`MULTS` are ArduPilot's standard unit and multiplier ids (``AP_Logger/LogStructure.h``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

#: ArduPilot's standard unit ids (AP_Logger/LogStructure.h) used by FMTU/UNIT
UNITS: dict[str, str] = {
    "-": "", "#": "instance", "?": "UNKNOWN", "A": "A", "a": "Ah", "d": "deg", "b": "B",
    "k": "deg/s", "D": "deglatitude", "e": "deg/s/s", "E": "rad/s", "G": "Gauss",
    "h": "degheading", "i": "A.s", "J": "W.s", "l": "l", "L": "rad/s/s", "m": "m", "n": "m/s",
    "o": "m/s/s", "O": "degC", "%": "%", "S": "satellites", "s": "s", "q": "rpm", "r": "rad",
    "U": "deglongitude", "u": "ppm", "v": "V", "P": "Pa", "w": "Ohm", "W": "Watt", "X": "W.h",
    "Y": "us", "z": "Hz",
}
#: ArduPilot's standard multiplier ids
MULTS: dict[str, float] = {
    "-": 0.0, "?": 1.0, "2": 1e2, "1": 1.0, "0": 1.0, "A": 1e-1, "B": 1e-2, "C": 1e-3,
    "D": 1e-4, "E": 1e-5, "F": 1e-6, "G": 1e-7, "I": 1e-9, "!": 3.6, "/": 3600.0,
}

FMTU_TYPE, UNIT_TYPE, MULT_TYPE, PARM_TYPE = 253, 252, 251, 129


@dataclass(frozen=True)
class MessageDef:
    """One DataFlash message type: what its ``FMT`` (and ``FMTU``) records declare.

    Parameters
    ----------
    name : str
        Message name, at most 4 ASCII characters.
    type_id : int
        Type byte 0..255, unique in a log (128 is ``FMT`` itself).
    fmt : str
        Format characters, one per field (at most 16).
    labels : str
        Comma-separated field names, one per format character.
    units, mults : str or None
        Unit / multiplier id characters (:data:`UNITS`, :data:`MULTS`), one per field; with
        ``units`` the writer also emits ``FMTU`` (and the ``UNIT``/``MULT`` rows it needs).
    """

    name: str
    type_id: int
    fmt: str
    labels: str
    units: str | None = None
    mults: str | None = None

    def as_kwargs(self) -> dict:
        """The keywords of :meth:`DataFlashWriter.define` (``w.define(**m.as_kwargs())``)."""
        return asdict(self)


#: The unit tables of modern logs, declared (without units) before the first FMTU.
UNIT = MessageDef("UNIT", UNIT_TYPE, "QbZ", "TimeUS,Id,Label")
MULT = MessageDef("MULT", MULT_TYPE, "Qbd", "TimeUS,Id,Mult")
FMTU = MessageDef("FMTU", FMTU_TYPE, "QBNN", "TimeUS,FmtType,UnitIds,MultIds")

#: ``PARM`` as :meth:`DataFlashWriter.write_params` declares it when the caller has not.
PARM = MessageDef("PARM", PARM_TYPE, "QNf", "TimeUS,Name,Value", "s--", "F--")

#: The simulation radar message (see pipeline.io.dataflash, stream ``radar``): range as
#: measured (ρ + τ·ρ̇), direction cosines u, v, range rate.
RADR = MessageDef("RADR", 120, "QBffff", "TimeUS,I,Rng,U,V,RR", "s#m--n", "F-0000")

_RC14 = "TimeUS," + ",".join(f"C{k}" for k in range(1, 15))
_RC8 = "TimeUS," + ",".join(f"C{k}" for k in range(1, 9))

#: layout -> its messages, in declaration order.
MESSAGES: dict[str, tuple[MessageDef, ...]] = {
    "ardupilot4": (
        MessageDef("PARM", 32, "QNf", "TimeUS,Name,Value", "s--", "F--"),
        MessageDef("MSG", 59, "QZ", "TimeUS,Message", "s-", "F-"),
        MessageDef("GPS", 84, "QBBIHBcLLeffffB",
                   "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
                   "s#---SmDUmnhnh-", "F----0BGGB000--"),
        MessageDef("GPA", 85, "QBCCCCfBIHf", "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta,Und",
                   "s#mmmnd-ssm", "F-BBBB0-CC0"),
        MessageDef("RCIN", 60, "Q" + "H" * 14, _RC14, "s" + "Y" * 14, "F" + "-" * 14),
        MessageDef("RCOU", 62, "Q" + "H" * 14, _RC14, "s" + "Y" * 14, "F" + "-" * 14),
        MessageDef("BARO", 64, "QBffcfIffB", "TimeUS,I,Alt,Press,Temp,CRt,SMS,Offset,GndTemp,Health",
                   "s#mPOnsmO-", "F-00B0C?0-"),
        MessageDef("ORGN", 69, "QBLLe", "TimeUS,Type,Lat,Lng,Alt", "s#DUm", "F-GGB"),
        MessageDef("ATT", 68, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF",
                   "sddddhhdh-", "FBBBBBBBB-"),
        MessageDef("RFND", 106, "QBCBB", "TimeUS,Instance,Dist,Stat,Orient", "s#m--", "F-B--"),
        MessageDef("MODE", 112, "QMBB", "TimeUS,Mode,ModeNum,Rsn", "s---", "F---"),
        MessageDef("IMU", 162, "QBffffffIIfBBHH",
                   "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz",
                   "s#EEEooo--O--zz", "F-000000-----00"),
        MessageDef("EV", 179, "QB", "TimeUS,Id", "s-", "F-"),
        RADR,
    ),
    "demo": (
        PARM,
        MessageDef("MSG", 130, "QZ", "TimeUS,Message", "s-", "F-"),
        MessageDef("GPS", 131, "QBIHBcLLefffB", "TimeUS,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,U",
                   "s---SmDUmnhn-", "F---0BGGB000-"),
        MessageDef("IMU", 132, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ", "sEEEooo", "F000000"),
        MessageDef("ATT", 133, "QccccCC", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw", "sddddhh", "FBBBBBB"),
        MessageDef("BARO", 134, "QffcB", "TimeUS,Alt,Press,Temp,Health", "smPO-", "F00B-"),
        MessageDef("MAG", 135, "Qhhh", "TimeUS,MagX,MagY,MagZ", "sGGG", "FCCC"),
        MessageDef("RCIN", 136, "Q" + "H" * 8, _RC8, "s" + "Y" * 8, "F" + "0" * 8),
        MessageDef("RCOU", 137, "Q" + "H" * 8, _RC8, "s" + "Y" * 8, "F" + "0" * 8),
        MessageDef("MODE", 138, "QMBB", "TimeUS,Mode,ModeNum,Rsn", "s---", "F---"),
        MessageDef("EV", 139, "QB", "TimeUS,Id", "s-", "F-"),
        MessageDef("RFND", 140, "QBCBB", "TimeUS,Instance,Dist,Stat,Orient", "s#m--", "F-B--"),
        MessageDef("XKF1", 141, "QBccCffffff", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,PN,PE,PD",
                   "s#ddhnnnmmm", "F-BBB000000"),
        MessageDef("ORGN", 142, "QBLLe", "TimeUS,Type,Lat,Lng,Alt", "s#DUm", "F-GGB"),
    ),
}


def layout(name: str) -> tuple[MessageDef, ...]:
    """The messages of layout ``name`` (a key of :data:`MESSAGES`) in declaration order."""
    try:
        return MESSAGES[name]
    except KeyError:
        raise KeyError(f"unknown DataFlash layout {name!r}; known: {', '.join(MESSAGES)}") from None
