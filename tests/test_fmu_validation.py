"""The suite's ``validate_fmu`` (tests/fmu_validation.py) finds what fmpy's
finds: its memory of parsed variable names changes the cost, not the verdict."""
from __future__ import annotations

import zipfile

from fmpy.validation import validate_fmu as fmpy_validate_fmu

from fmu_models.export.build import cached_fmu
from fmu_models.models.wind_gust import WIND_GUST
from tests.fmu_validation import validate_fmu


def _renamed(source, target, old: str, new: str):
    """``source`` with the variable ``old`` called ``new`` in its modelDescription."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(f'name="{old}"'.encode(), f'name="{new}"'.encode())
            zout.writestr(item, data)
    return target


def _as_reported(problems: list[str]) -> list[tuple[str, frozenset[str]]]:
    """Each problem with the parser's "Expected one of" list as a set: lark
    lists the terminals of a set, in an order that changes with the
    process's string hashing, so two processes word one verdict in two
    orders (and the verdict kept on disk was worded by another process)."""
    out = []
    for text in problems:
        head, _, expected = text.partition("Expected one of:")
        out.append((head, frozenset(line.strip() for line in expected.splitlines() if line.strip())))
    return out


def test_an_illegal_name_is_reported_as_fmpy_reports_it_every_time_it_is_met(tmp_path):
    stock = cached_fmu(WIND_GUST, 2)
    assert validate_fmu(str(stock)) == fmpy_validate_fmu(str(stock)) == []
    # the same illegal name in two FMUs of other bytes: the second meets it remembered
    first = _renamed(stock, tmp_path / "a.fmu", "v_wind_x", "1v_wind_x")
    second = _renamed(stock, tmp_path / "b.fmu", "v_wind_x", "1v_wind_x")
    with zipfile.ZipFile(second, "a") as z:
        z.writestr("documentation/readme.txt", "other bytes, same names")
    for fmu in (first, second):
        problems = validate_fmu(str(fmu))
        assert _as_reported(problems) == _as_reported(fmpy_validate_fmu(str(fmu)))
        assert len(problems) == 1 and '"1v_wind_x"' in problems[0] and "not a legal variable name" in problems[0]


def test_a_plain_name_accepted_unparsed_is_one_fmpys_parser_accepts():
    """The shortcut of tests/fmu_validation.py: the grammar it was read from is
    the installed fmpy's (else every name is parsed, and this test says the
    shortcut is off), and every name it accepts unparsed, ours and the
    grammar's corners, fmpy's parser accepts; names outside it still go to
    the parser (a quoted name, a space, an index that is no number)."""
    import inspect

    import fmpy.validation
    import lark

    from fmu_models.models.estimator import ESTIMATOR
    from tests import fmu_validation

    source = inspect.getsource(fmpy.validation._validate_variable_names)
    grammar = source.split('grammar = r"""', 1)[1].split('"""', 1)[0]
    parser = fmu_validation._NameParser(grammar, start="name")
    assert parser.plain
    earley = lark.Lark(grammar, start="name")
    ours = [v.name for v in ESTIMATOR.variables] + [v.name for v in WIND_GUST.variables]
    corners = ["x", "_", "a1_B", "a.b", "a[1]", "a[1,22].b_c[3]", "a.b.c", "der(x)", "der(a.b[2],2)", "der", "dera"]
    for name in ours + corners:
        assert fmu_validation._PLAIN.fullmatch(name), name
        earley.parse(name)  # raises if not legal
    for name in ("'q x'", "a b", "a[i]", "a[]", "1a", "der(x", "a..b", "a.", "x\n"):
        assert not fmu_validation._PLAIN.fullmatch(name), name
