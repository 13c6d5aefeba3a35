"""Private names of other libraries the project relies on where they have no
public way, each pinned: the name exists and does what we rely on, so a
version that changes it fails here, naming it, instead of silently costing
time (docs/dependencies.md lists every such use, what breaks and why).

Pinned elsewhere: fmpy's ``_loadFunctions``/``_functions``
(tests/engine/test_fmpy_classes.py), fmpy's name grammar in
``_validate_variable_names`` (tests/test_fmu_validation.py), python-control's
``FRD._ifunc`` (tests/paper/test_stability_linear.py, the margins to the bit),
CasADi's generated C (tests/fmus/test_c_spelling.py)."""
from __future__ import annotations

import pytest

from tests import conftest


def test_pytests_rewrite_functions_write_the_bytecode_its_import_reads(tmp_path, request):
    """tests/conftest.py's ``_write_rewritten`` (``_pytest.assertion.rewrite``'s
    ``_rewrite_test``, ``_write_pyc``, ``get_cache_dir``, ``PYC_TAIL``...)
    writes a test module's bytecode that pytest's import takes as it is
    (``_read_pyc``), with the asserts rewritten; a second call finds it
    current and writes nothing."""
    from _pytest.assertion.rewrite import PYC_TAIL, _read_pyc, get_cache_dir

    source = tmp_path / "test_pinned.py"
    source.write_text("def test_it():\n    values = [1, 2]\n    assert values == [1, 3]\n")
    assert conftest._write_rewritten(source, request.config) is True
    pyc = get_cache_dir(source) / ("test_pinned" + PYC_TAIL)
    code = _read_pyc(source, pyc)
    assert code is not None, f"pytest's import does not read {pyc}"
    namespace: dict = {}
    exec(code, namespace)
    with pytest.raises(AssertionError) as failed:
        namespace["test_it"]()
    assert "[1, 2] == [1, 3]" in str(failed.value)  # rewritten: the values are told
    assert conftest._write_rewritten(source, request.config) is False
    source.write_text(source.read_text() + "\n")  # another source: written again
    assert conftest._write_rewritten(source, request.config) is True


@pytest.fixture(scope="module")
def made_once_for_the_module():
    return object()


def test_a_test_with_a_module_fixture_is_seen_to_share_it(request, made_once_for_the_module):
    """tests/conftest.py's ordering reads a test's fixture definitions
    (``item._fixtureinfo.name2fixturedefs``, each with its ``scope``)."""
    assert hasattr(request.node, "_fixtureinfo"), "pytest's Item._fixtureinfo is gone"
    assert conftest._shares_module_fixture(request.node)


def test_a_test_without_one_is_not(request):
    assert hasattr(request.node, "_fixtureinfo"), "pytest's Item._fixtureinfo is gone"
    assert not conftest._shares_module_fixture(request.node)


def test_fmpys_validation_builds_its_name_parser_through_lark_at_the_call(quadrotor_fmu2):
    """tests/fmu_validation.py hands fmpy its kept name parser by patching
    ``lark.Lark`` for the call: fmpy's ``_validate_variable_names`` imports
    it inside the call (fmpy 0.3). A fmpy that binds it elsewhere would
    build its own parser again each call."""
    from tests import fmu_validation

    before = fmu_validation._PARSER.cache_info()
    assert fmu_validation._validated(str(quadrotor_fmu2)) == []
    after = fmu_validation._PARSER.cache_info()
    assert after.hits + after.misses == before.hits + before.misses + 1, "fmpy did not take the patched lark.Lark"
