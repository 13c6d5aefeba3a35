"""The paper as an application of the co-simulation engine: the missions of
Sarabakha & Kayacan (trajectories, the flight controller as a component,
the ``[wind]`` and ``[metrics]`` sections, the shipped scenarios), Tables 2
and 3 beside the paper's, the figures, the report, the linear stability
analysis and the ``fnn-cosim`` command line.

Importing the package registers its component kinds, sections, FMU models
and scenarios with :mod:`cosim.scenario.registry` (see :mod:`.components`).
"""
from .components import register

register()
