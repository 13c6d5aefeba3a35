"""The FMU lifecycle: an FMI 2.0 / 3.0 FMU (Co-Simulation or Model Exchange)
loaded through fmpy, instantiated, set up, stepped and freed
(:class:`FmuComponent`: :mod:`.fmu` reads the file, :mod:`.lifecycle`,
:mod:`.variables`, :mod:`.state` and :mod:`.step` are its jobs); its model description read once and kept
(:mod:`.description`, :mod:`.description_cache`); Model Exchange FMUs
integrated together in C (:mod:`.me_system`, :mod:`.model_exchange`); the
FMUs' own log (:mod:`.log`), their units (:mod:`.units`) and what the
compiled loop needs to call one (:mod:`.c_calls`).

Owns everything that touches an FMU's binary or its modelDescription.xml.
May import the engine's foundation modules (``cosim.errors``, ``cosim.files``,
``cosim.component``, ``cosim.native``, ...) and nothing else of the engine:
it knows no scenario, no loop, no study.
"""
from ..surface import lazy_surface

_SURFACE = {
    "FmuComponent": "fmu",
    "read_description": "fmu",
    "stream_seed": "lifecycle",
    "fmu_ports": "description",
    "kept_description": "description_cache",
    "ModelExchangeSystem": "me_system",
    "SolverSettings": "model_exchange",
    "IntegrationError": "model_exchange",
    "fmu_log": "log",
    "Unit": "units",
    "conversion": "units",
}
__all__ = list(_SURFACE)
__getattr__, __dir__ = lazy_surface(__name__, _SURFACE)
