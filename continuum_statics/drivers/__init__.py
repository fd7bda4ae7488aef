"""Cable actuator backends for ``cable_driver``: the interface and the backends."""
from continuum_statics.drivers.base import (
    ENTRY_POINT_GROUP,
    BackendOption,
    BackendStatus,
    CableBackend,
    CableReading,
    ConnectionLost,
    RosTopicBackend,
    backend_class,
)

__all__ = ['backend_class', 'BackendOption', 'BackendStatus', 'CableBackend', 'CableReading',
           'ConnectionLost', 'ENTRY_POINT_GROUP', 'RosTopicBackend']
