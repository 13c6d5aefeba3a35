"""Fixed-step co-simulation of FMUs (FMI 2.0 / 3.0 through fmpy) and Python
components, with the paper's missions as TOML scenarios and the ``fnn-cosim``
command line. See ``docs/cosim.md``; the entry points are
:func:`cosim.scenario.load_scenario`, :func:`cosim.scenario.build_master` and
:class:`cosim.master.Master`.
"""
