"""Shared fixtures: FMUs are built once per test session (content-addressed
cache, so an unchanged model is not rebuilt across sessions either).

With several workers (``make test``: pytest-xdist) the controller builds
every shipped FMU before the workers start, side by side on every core
(:func:`cosim.scenario.registry.build_fmu_models`): each FMU is built once, not by
whichever workers first need it at the same time, and a fresh clone's first
build takes the compilers' time over the cores. A run on one process builds
what its tests use, when they use it."""
from __future__ import annotations

import pytest

from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import QUADROTOR


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session):
    if session.config.pluginmanager.has_plugin("dsession"):  # the xdist controller, before its workers
        import quadrotor_paper  # noqa: F401  (registers the shipped models)
        from cosim.scenario import registry
        from fmu_models.export.build import FMI_VERSIONS

        registry.build_fmu_models(sorted(FMI_VERSIONS))


@pytest.hookimpl(tryfirst=True)
def pytest_collection(session):
    """In a worker of several (pytest-xdist), this worker's share of the
    test modules rewritten and written to their ``__pycache__`` before it
    collects (:func:`_rewrite_share`)."""
    import os
    import sys

    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if worker.startswith("gw") and count > 1 and not sys.dont_write_bytecode:
        _rewrite_share(session, int(worker[2:]) % count, count)


def _share(files, index: int, count: int) -> list:
    """Worker ``index``'s share of ``files`` (paths), dealt out by size,
    largest first, to the worker with the fewest bytes so far; in path
    order (the order of collection)."""
    shares: list[list] = [[] for _ in range(count)]
    sizes = [0] * count
    for size, f in sorted(((f.stat().st_size, f) for f in files), reverse=True):
        least = sizes.index(min(sizes))
        shares[least].append(f)
        sizes[least] += size
    return sorted(shares[index])


def _rewrite_share(session, index: int, count: int) -> None:
    """Every worker collects every test module, and pytest rewrites a test
    module's asserts at its import unless its rewritten bytecode is cached
    (``__pycache__/*-pytest-*.pyc``, keyed by the source's hash). In a fresh
    clone the workers would each rewrite all of them side by side (~4.5
    CPU-s each: parsing, the rewrite, compiling ~1 MB of tests), so each
    first writes its share (:func:`_share`), and then finds the other's
    written as it collects: a file not written yet is rewritten at its
    import as before. Pytest's own functions do the rewrite
    (:func:`_write_rewritten`), so the bytecode is the one its import would
    write. docs/fmi-export.md, "The test modules' assertion rewriting"."""
    config = session.config
    if config.getoption("assertmode", "rewrite") != "rewrite":
        return
    from fnmatch import fnmatch

    try:
        patterns = [p for p in config.getini("python_files") if "/" not in p] + ["conftest.py"]
        files = set()
        for arg in config.args:
            path = config.invocation_params.dir / arg.split("::")[0]
            found = path.rglob("*.py") if path.is_dir() else [path]
            files.update(f.resolve() for f in found
                         if "__pycache__" not in f.parts and any(fnmatch(f.name, p) for p in patterns))
        for fn in _share(files, index, count):
            try:
                _write_rewritten(fn, config)
            except (OSError, SyntaxError, ValueError):  # its import says why, as before
                continue
    except (ImportError, AttributeError, KeyError, OSError):  # another pytest: its imports rewrite, as before
        return  # (and tests/test_private_apis.py fails, naming what changed)


def _write_rewritten(fn, config) -> bool:
    """The test module ``fn``'s asserts rewritten and written to its
    ``__pycache__`` as pytest's import writes them; ``False`` when the file
    there is already the one for ``fn``'s source (a warm tree, or the other
    worker). Pytest has no public API for this: its private functions are
    used, pinned by tests/test_private_apis.py (docs/dependencies.md)."""
    import importlib.util

    from _pytest.assertion.rewrite import (PYC_TAIL, _rewrite_test, _write_pyc, assertstate_key, get_cache_dir,
                                           try_makedirs)

    cache_dir = get_cache_dir(fn)
    pyc = cache_dir / (fn.name[:-3] + PYC_TAIL)
    try:
        with open(pyc, "rb") as fp:
            head = fp.read(16)
        if head[:4] == importlib.util.MAGIC_NUMBER and \
                head[8:16] == importlib.util.source_hash(fn.read_bytes())[:8]:
            return False
    except OSError:
        pass
    if not try_makedirs(cache_dir):
        return False
    source_hash, co = _rewrite_test(fn, config)
    return _write_pyc(config.stash[assertstate_key], co, source_hash, pyc)


def pytest_sessionfinish(session):
    """The folders the tests' fmpy harnesses extracted FMUs to, removed
    (tests/catalog_fmus.py: fmpy's ``extract`` alone leaves them in the
    system's temporary folder); in each process that made some."""
    import sys

    made = sys.modules.get("tests.catalog_fmus")
    if made is not None:
        made.remove_extracted()


@pytest.fixture(scope="module")
def one_extraction():
    """A module's masters load the libraries of the FMUs this tool built
    from the one folder the cache extracted them to, as a study's masters do
    (:func:`cosim.fmi.description_cache.shared_extraction`; they keep no
    writable global state): a master built after the first in a process
    extracted each of its FMUs again and removed it when closed (about 5 ms
    an FMU). A module asks for it with
    ``pytestmark = pytest.mark.usefixtures("one_extraction")``."""
    from cosim.fmi.description_cache import shared_extraction

    with shared_extraction():
        yield


@pytest.fixture(scope="session")
def quadrotor_fmu2():
    """Path of the FMI 2.0 (ME + CS) quadrotor FMU."""
    return cached_fmu(QUADROTOR, 2)


@pytest.fixture(scope="session")
def industrial_fmus(tmp_path_factory):
    """``industrial_fmus(spec) -> Path``: tests/industrial_fmus.py's ``build`` into one folder of the
    test process, so each FMU (and the generic C layer) is compiled once a process."""
    from tests.industrial_fmus import build

    folder = tmp_path_factory.mktemp("industrial_fmus")
    return lambda spec: build(folder, spec)


# The longest tests (wall time in a fresh ``make test``, parametrized ones
# summed; longest first), run first: pytest-xdist hands each process a
# contiguous share of the collection and the first to run out steals from
# the end of the other's, so a long test left at the end keeps one process
# busy while the other waits. A test using a module-scoped fixture moves with
# its whole module, so that fixture is still made once. A name no longer
# collected is ignored. Measured at 0adb59c (the tests of 1.3 s and more).
LONGEST_FIRST = (
    "tests/paper/test_stability_cosim.py::test_command_writes_the_report_and_figures",
    "tests/paper/test_estimation_gating.py::test_fmpy_simulate_ssp_flies_circles_estimated_without_chasing_its_first_fix",
    "tests/paper/test_calibrate_plant.py::test_the_hidden_parameters_and_the_wind_recovered_to_1e_6_from_guesses_far_off",
    "tests/paper/test_sweep.py::test_a_running_scheduler_and_two_workers_by_address",
    "tests/paper/test_ssp_importers.py::test_every_input_is_connected_and_every_fmu_starts_from_the_bound_values",
    "tests/engine/test_engine_calibration.py::test_van_der_pol_mu_from_noisy_data_of_our_own_inside_its_interval",
    "tests/paper/test_ssp_importers.py::test_fmpy_flies_the_circles_archive_within_3_percent_of_our_master",
    "tests/paper/test_calibrate_plant.py::test_the_casadi_way_and_the_fmu_way_give_the_same_estimates",
    "tests/paper/test_fuzz.py::test_fuzz_scenario_files",
    "tests/paper/test_stability_cosim.py::test_operating_point_figures_drawn_aside_are_the_same_files",
    "tests/paper/test_estimation.py::test_the_estimated_missions_as_fmus_fly_in_libcosim_as_in_our_master",
    "tests/paper/test_fuzz.py::test_fuzz_archives",
    "tests/paper/test_stability_along_flight.py::test_the_study_runs_every_case_through_the_study_runner_in_case_order",
    "tests/test_imports.py::test_importing_every_engine_module_loads_no_application_package",
    "tests/engine/test_engine_study.py::test_a_local_dask_cluster_gives_the_rows_of_this_process",
    "tests/engine/test_engine_fmu_log.py::test_the_tool_runs_no_fmu_through_fmpys_own_simulation",
    "tests/paper/test_calibrate_plant.py::test_the_calibrated_parameter_set_flies_in_a_run_and_in_an_exported_archive",
    "tests/paper/test_calibrate_plant.py::test_a_parameter_the_flight_does_not_excite_is_not_identifiable",
    "tests/paper/test_fuzz.py::test_fuzz_learned_files",
    "tests/fmus/test_sensors_ssp.py::test_circles_sensors_flies_in_libcosim_as_in_our_master_noise_and_seed_included",
    "tests/fmus/test_build_cache.py::test_the_library_is_the_one_a_single_compiler_call_makes",
    "tests/paper/test_stability_linear.py::test_feed_forward_leaves_poles_and_margins_and_removes_the_v_over_kp_ramp_lag",
    "tests/fmus/test_fmi3.py::test_source_fmu_compiles_with_fmpy_build",
    "tests/paper/test_sweep.py::test_every_run_is_a_row_with_the_metrics_of_a_single_run",
    "tests/paper/test_long_missions.py::test_a_runs_peak_memory_is_flat_in_its_duration",
    "tests/paper/test_ssp_libcosim.py::test_the_whole_mission_as_fmus_flies_in_libcosim_as_in_our_master",
    "tests/engine/test_engine_fmu_log.py::test_only_the_fmu_component_and_the_file_guard_import_fmpys_fmi_layers_or_extract",
    "tests/test_fmu_validation.py::test_a_plain_name_accepted_unparsed_is_one_fmpys_parser_accepts",
    "tests/paper/test_estimation_gating.py::test_a_fix_that_jumps_is_refused_counted_and_leaves_the_estimate_as_without_it",
    "tests/paper/test_calibrate_plant.py::test_an_instance_of_a_scenario_driven_by_the_log",
    "tests/fmus/test_sensors_ssp.py::test_the_archive_flies_as_the_toml_scenario_in_the_feedthrough_ordering",
    "tests/fmus/test_plant_fmu.py::test_source_fmu_compiles_on_its_own_with_fmpy_build",
    "tests/test_imports.py::test_the_graph_sees_imports_inside_functions_and_relative_ones",
    "tests/paper/test_linearize_cli.py::test_linearize_the_plant_at_hover_writes_the_casadi_jacobian",
    "tests/paper/test_plant_model_exchange.py::test_circles_with_the_plant_as_model_exchange_lands_on_the_co_simulation_run",
    "tests/paper/test_fuzz.py::test_fuzz_study_files",
    "tests/paper/test_estimation_gating.py::test_measurements_a_step_late_with_their_stamps_give_the_on_time_estimate",
)


def _shares_module_fixture(item) -> bool:
    """Whether ``item`` uses a fixture made once for its module, class or
    package (pytest has no public API for a test's fixture definitions: its
    ``_fixtureinfo`` is read, pinned by tests/test_private_apis.py; without
    it, no test moves with its module)."""
    info = getattr(item, "_fixtureinfo", None)
    return info is not None and any(
        d.scope in ("module", "class", "package") for defs in info.name2fixturedefs.values() for d in defs)


@pytest.hookimpl(trylast=True)  # after pytest's own ordering by fixture
def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    first: dict[int, list] = {}
    modules = {}
    for item in items:
        i = rank.get(item.nodeid.split("[")[0])
        if i is None:
            continue
        if _shares_module_fixture(item):
            modules.setdefault(item.path, i)
        else:
            first.setdefault(i, []).append(item)
    by_path: dict = {}
    for item in items:
        by_path.setdefault(item.path, []).append(item)
    for path, i in modules.items():  # the whole module where the test is, in its order
        first.setdefault(i, []).extend(by_path[path])
    moved = [it for i in sorted(first) for it in first[i]]
    seen = set()
    moved = [it for it in moved if not (id(it) in seen or seen.add(id(it)))]
    ids = {id(it) for it in moved}
    items[:] = moved + [it for it in items if id(it) not in ids]
