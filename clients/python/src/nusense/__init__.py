"""Python client of the nusense daemon: the NUSense tactile sensors on a network, over Zenoh.

    import nusense

    with nusense.connect() as client:  # the daemon on this machine (tcp/127.0.0.1:7447)
        for serial in client.sensors():
            print(serial, client.status(serial).problems)
        with client.readings() as stream:
            for reading in stream:
                ...
"""

from .client import DEFAULT_ENDPOINT, Client, SensorEvent, SensorWatch, Stream, config, connect
from .errors import DaemonError, NoReplyError, NusenseError, ProtocolError
from .reading import (
    SCHEMA_VERSION,
    CameraMotion,
    Contact,
    Contacts,
    ContactTest,
    Estimate,
    LatticeCounts,
    LedState,
    PressureMap,
    Reading,
    ShearField,
    decode_contacts,
    decode_reading,
)
from .status import Status, decode_status

__version__ = "0.1.0"

__all__ = [
    "DEFAULT_ENDPOINT",
    "SCHEMA_VERSION",
    "CameraMotion",
    "Client",
    "Contact",
    "Contacts",
    "ContactTest",
    "DaemonError",
    "Estimate",
    "LatticeCounts",
    "LedState",
    "NoReplyError",
    "NusenseError",
    "PressureMap",
    "ProtocolError",
    "Reading",
    "SensorEvent",
    "SensorWatch",
    "Stream",
    "ShearField",
    "Status",
    "config",
    "connect",
    "decode_contacts",
    "decode_reading",
    "decode_status",
]
