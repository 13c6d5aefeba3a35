"""A fixed-step co-simulation engine: FMUs (FMI 2.0 / 3.0 through fmpy) and
Python components, joined by checked connections, recorded as they run,
guarded against divergence, described by TOML scenarios.

The engine knows no model and no mission: component kinds, scenario sections,
models built on demand and shipped scenarios are registered by the packages
that provide them (:mod:`cosim.scenario.registry`). It is six packages on a
foundation (the modules here), each importing only the layers below:
:mod:`cosim.fmi`, :mod:`cosim.loop`, :mod:`cosim.scenario`, then
:mod:`cosim.study`, :mod:`cosim.ssp`, :mod:`cosim.linearize`, then
:mod:`cosim.calibration`. Entry points, each named by its package's surface:
:func:`cosim.scenario.load_scenario`, :func:`cosim.scenario.build_master`,
:class:`cosim.loop.Master` and :meth:`cosim.loop.Master.run`;
:func:`cosim.study.load_study` and :func:`cosim.study.run_study`;
:func:`cosim.linearize.linearize_fmu`; :func:`cosim.ssp.export_ssp` and
:func:`cosim.ssp.load_ssp`. Each documents every argument it takes (a test
reads this list). See ``docs/cosim.md``.
"""
