"""Cable actuator backends for ``cable_driver``: the interface and the simulated backend."""
from continuum_statics.drivers.base import (
    ENTRY_POINT_GROUP,
    BackendOption,
    BackendStatus,
    CableBackend,
    CableReading,
    backend_class,
)

__all__ = ['backend_class', 'BackendOption', 'BackendStatus', 'CableBackend', 'CableReading',
           'ENTRY_POINT_GROUP']
