"""cosim.loop.connection on its own: parsing, brace expansion and every refusal of
check_connections, with stand-in components that only carry Port tuples."""
from __future__ import annotations

import re
from types import SimpleNamespace

import pytest

from cosim.component import Port, ports
from cosim.loop.connection import Connection, Endpoint, check_connections, parse_connection, parse_connections
from cosim.errors import ConnectionCheckError, CosimError


def C(src: str, dst: str) -> Connection:
    (a, _, b), (c, _, d) = src.partition("."), dst.partition(".")
    return Connection(Endpoint(a, b), Endpoint(c, d))


# ---- parsing ---------------------------------------------------------------------------------

def test_parse_one_connection():
    assert parse_connection("A.out -> B.in") == [C("A.out", "B.in")]
    assert parse_connection("  A.out->B.in  ") == [C("A.out", "B.in")]
    assert str(parse_connection("A.out -> B.in")[0]) == "A.out -> B.in"
    assert str(Endpoint("A", "x")) == "A.x"


def test_variable_names_may_contain_dots():
    """Only the first dot separates the component (FMU names like body.v are kept whole)."""
    assert parse_connection("Plant.body.v -> ctrl.v") == [C("Plant.body.v", "ctrl.v")]
    assert parse_connection("Plant.body.v -> ctrl.v")[0].source == Endpoint("Plant", "body.v")


def test_brace_groups_expand_pairwise():
    assert parse_connection("P.{x,y,z} -> c.{a, b ,c}") == [C("P.x", "c.a"), C("P.y", "c.b"), C("P.z", "c.c")]
    # a group may stand anywhere in the side, also in the component name or mid-name
    assert parse_connection("{A,B}.out -> C.in_{1,2}") == [C("A.out", "C.in_1"), C("B.out", "C.in_2")]
    assert parse_connection("P.{x} -> c.y") == [C("P.x", "c.y")]


def test_brace_group_on_one_side_only_must_be_a_single_item():
    with pytest.raises(ConnectionCheckError, match=re.escape(
            "connection 'P.{x,y} -> c.u': 2 sources but 1 destinations")):
        parse_connection("P.{x,y} -> c.u")
    with pytest.raises(ConnectionCheckError, match="3 sources but 2 destinations"):
        parse_connection("P.{x,y,z} -> c.{a,b}")


def test_parse_connections_concatenates_in_order():
    assert parse_connections(["A.{x,y} -> B.{x,y}", "B.z -> A.z"]) == [
        C("A.x", "B.x"), C("A.y", "B.y"), C("B.z", "A.z")]
    assert parse_connections([]) == []


@pytest.mark.parametrize("text, message", [
    ("A.out B.in", "connection 'A.out B.in' must be a string 'A.out -> B.in'"),
    ("A.x -> B.y -> C.z", "connection 'A.x -> B.y -> C.z' must be a string 'A.out -> B.in'"),
    (42, "connection 42 must be a string 'A.out -> B.in'"),
    (None, "connection None must be a string"),
    ("A -> B.in", "connection 'A -> B.in': 'A' is not of the form Component.variable"),
    ("A.out -> .in", "connection 'A.out -> .in': '.in' is not of the form Component.variable"),
    ("A.out -> B.", "connection 'A.out -> B.': 'B.' is not of the form Component.variable"),
    (" -> B.in", "connection ' -> B.in': '' is not of the form Component.variable"),
    ("A.{x,} -> B.{p,q}", "connection 'A.{x,} -> B.{p,q}': 'A.' is not of the form Component.variable"),
    ("{A,B}.{x,y} -> C.{p,q}", "at most one {a,b,...} group per side"),
])
def test_malformed_connections_are_refused(text, message):
    with pytest.raises(ConnectionCheckError, match=re.escape(message)):
        parse_connection(text)


def test_errors_are_cosim_errors():
    assert issubclass(ConnectionCheckError, CosimError)


# ---- checking --------------------------------------------------------------------------------

def stand_in(inputs=(), outputs=(), variables=None):
    comp = SimpleNamespace(inputs=tuple(inputs), outputs=tuple(outputs))
    if variables is not None:
        comp.variables = {name: SimpleNamespace(causality=c) for name, c in variables.items()}
    return comp


@pytest.fixture
def components():
    return {
        "src": stand_in(outputs=ports(("x", "m"), ("v", "m/s"), "free")),
        "sink": stand_in(inputs=ports(("x", "m"), ("v", "m/s"), "free", ("w", None))),
        "ints": stand_in(inputs=(Port("count", None, "Int32"),), outputs=(Port("n", None, "Int32"),)),
        "fmu": stand_in(inputs=ports(("u", "m")), outputs=ports(("y", "m")),
                        variables={"u": "input", "y": "output", "tau": "parameter", "t_int": "independent",
                                   "dummy": "local"}),
    }


def check(texts, comps):
    return check_connections(parse_connections(texts), comps)


def test_good_connections_are_returned_in_order(components):
    texts = ["src.{x,v} -> sink.{x,v}", "fmu.y -> sink.free", "src.x -> fmu.u"]
    assert check(texts, components) == [C("src.x", "sink.x"), C("src.v", "sink.v"), C("fmu.y", "sink.free"),
                                        C("src.x", "fmu.u")]


def test_one_output_may_feed_many_inputs(components):
    assert len(check(["src.x -> sink.x", "src.x -> fmu.u"], components)) == 2


def test_a_missing_unit_on_either_side_skips_the_unit_check(components):
    # src.free has no unit, sink.x has one; src.x has one, sink.w has none
    assert len(check(["src.free -> sink.x", "src.x -> sink.w"], components)) == 2


@pytest.mark.parametrize("texts, message", [
    (["nope.x -> sink.x"], "connection nope.x -> sink.x: unknown component 'nope'; components are: fmu, ints, sink, src"),
    (["src.x -> nope.x"], "connection src.x -> nope.x: unknown component 'nope'"),
    (["src.q -> sink.x"], "connection src.q -> sink.x: source src.q does not exist (its outputs are: x, v, free)"),
    (["src.x -> sink.q"], "connection src.x -> sink.q: destination sink.q does not exist (its inputs are: x, v, free, w)"),
    (["src.x -> src.q"], "connection src.x -> src.q: destination src.q does not exist (its inputs are: none)"),
    (["sink.x -> src.x"], "connection sink.x -> src.x: source sink.x is an input, not an output"),
    (["src.x -> fmu.y"], "connection src.x -> fmu.y: destination fmu.y is an output, not an input"),
    (["fmu.u -> sink.x"], "connection fmu.u -> sink.x: source fmu.u is an input, not an output"),
    (["fmu.tau -> sink.x"], "connection fmu.tau -> sink.x: source fmu.tau is a parameter, not an output"),
    (["src.x -> fmu.tau"], "connection src.x -> fmu.tau: destination fmu.tau is a parameter, not an input"),
    (["fmu.t_int -> sink.x"], "source fmu.t_int is an independent, not an output"),
    (["fmu.dummy -> sink.x"], "source fmu.dummy is a local, not an output"),
    (["src.v -> sink.x"], "connection src.v -> sink.x: unit mismatch, src.v is in m/s (SI m.s-1) but sink.x is in m, "
                          "not one quantity; state the conversion, { connect = \"src.v -> sink.x\", factor = ..., "
                          "offset = ... } (sink.x = factor * src.v + offset), or mark it "
                          "{ connect = \"src.v -> sink.x\", units = \"unchecked\" }"),
    (["ints.n -> sink.free"], "connection ints.n -> sink.free: type mismatch, ints.n is Int32 but sink.free is Float64"),
    (["src.free -> ints.count"], "type mismatch, src.free is Float64 but ints.count is Int32"),
    (["src.x -> sink.x", "fmu.y -> sink.x"], "connection fmu.y -> sink.x: sink.x is already fed by src.x -> sink.x"),
    (["src.x -> sink.x", "src.x -> sink.x"], "connection src.x -> sink.x: sink.x is already fed by src.x -> sink.x"),
])
def test_wrong_connections_are_refused_naming_them(components, texts, message):
    with pytest.raises(ConnectionCheckError, match=re.escape(message)):
        check(texts, components)


def test_the_first_wrong_connection_is_the_one_named(components):
    with pytest.raises(ConnectionCheckError) as info:
        check(["src.x -> sink.x", "src.q -> sink.v", "nope.x -> sink.free"], components)
    assert str(info.value).startswith("connection src.q -> sink.v:")


def test_connection_objects_are_checked_like_strings(components):
    conn = Connection(Endpoint("src", "v"), Endpoint("fmu", "u"))
    with pytest.raises(ConnectionCheckError, match="unit mismatch"):
        check_connections([conn], components)


def test_endpoints_split_at_the_longest_known_instance_name():
    # an SSP archive's nested systems are flattened to dotted instance names (SuT.edrive_mass)
    (c,) = parse_connection("SuT.edrive_mass.x -> SuT.y", instances=("SuT", "SuT.edrive_mass"))
    assert c.source == Endpoint("SuT.edrive_mass", "x") and c.destination == Endpoint("SuT", "y")
    (c,) = parse_connections(["A.x[1] -> B.der(x[2])"], instances=())
    assert c.source == Endpoint("A", "x[1]") and c.destination == Endpoint("B", "der(x[2])")


def test_groups_split_outside_brackets_and_quotes():
    assert parse_connection("A.{x[1,2],'a,b', 'c.d'.e} -> B.{p,q,r}") == [
        C("A.x[1,2]", "B.p"), C("A.'a,b'", "B.q"), C("A.'c.d'.e", "B.r")]
    # a dot inside a quoted name is no endpoint separator
    assert parse_connection("'q.r'.x -> B.u")[0].source == Endpoint("'q.r'", "x")
