"""A fixed-step co-simulation engine: FMUs (FMI 2.0 / 3.0 through fmpy) and
Python components, joined by checked connections, recorded as they run,
guarded against divergence, described by TOML scenarios.

The engine knows no model and no mission: component kinds, scenario sections,
models built on demand and shipped scenarios are registered by the packages
that provide them (:mod:`cosim.registry`). Entry points:
:func:`cosim.scenario.load_scenario`, :func:`cosim.assembly.build_master`,
:class:`cosim.master.Master` and :meth:`cosim.master.Master.run`;
:func:`cosim.study.load_study` and :func:`cosim.study_run.run_study`;
:func:`cosim.linearize.linearize_fmu`; :func:`cosim.ssp_export.export_ssp` and
:func:`cosim.ssp.load_ssp`. Each documents every argument it takes (a test
reads this list). See ``docs/cosim.md``.
"""
