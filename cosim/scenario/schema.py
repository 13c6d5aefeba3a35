"""The declarations every file a user writes is checked against (pydantic v2).

A scenario, a study, an SSP archive's annotation, a learned-state file: each
section is declared once, as a :class:`Table` (a pydantic model: strict
types, unknown keys refused, field constraints), and the same declaration
gives the JSON Schema editors use (``fnn-cosim schema scenario``).

Errors keep the engine's one-line form, naming the key, the value and what
was expected (``simulation.step = 0.0: must be positive``,
``fmus.Plant.version: unknown key; known keys: fmi_version, model, ...``):
:func:`scenario_error` turns pydantic's first error into a
:class:`~cosim.errors.ScenarioError`. Domain checks (ranges of a parameter
dataclass, a model's variables, cross-references) raise :func:`refuse` from
validators and keep their own words.
"""
from __future__ import annotations

import functools
import math
import weakref
from typing import Annotated, Any, ClassVar, Iterable, Mapping

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, WithJsonSchema, model_validator
from pydantic_core import PydanticCustomError

from ..errors import ScenarioError

__all__ = ["Table", "ParameterTable", "Number", "Positive", "NonNegative", "Integer", "NonNegativeInt", "Count",
           "Strings", "Names", "one_of", "numbers", "dataclass_table", "refuse", "scenario_error", "where", "validate",
           "thawed", "json_schema"]

# A float of the document: an int is taken as a float, a bool or a string is not; never inf or nan.
Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0)]
NonNegative = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0)]
Integer = Annotated[int, Field(strict=True)]
NonNegativeInt = Annotated[int, Field(strict=True, ge=0)]
Count = Annotated[int, Field(strict=True, gt=0)]

_MISSING = object()


def refuse(message: str, *, key: str | None = None, value: Any = _MISSING) -> PydanticCustomError:
    """An error for a validator to raise: ``message`` about the table being
    validated, or about its ``key`` (with ``value``, shown as ``key = value``)."""
    ctx = {"message": message, "key": key or ""}
    if value is not _MISSING:
        ctx["value"] = value
    return PydanticCustomError("refused", "{message}", ctx)


_KNOWN: "weakref.WeakKeyDictionary[type, frozenset[str]]" = weakref.WeakKeyDictionary()  # a Table's known keys


class Table(BaseModel):
    """A table of a file a user writes: strict types, frozen, unknown keys
    refused naming the known ones (sorted, or in declaration order when
    ``known_in_order``)."""

    model_config = ConfigDict(strict=True, extra="forbid", frozen=True, allow_inf_nan=False,
                              populate_by_name=True, validate_default=False, defer_build=True)
    selector: ClassVar[str | None] = None  # a key that picks the table's kind, allowed but no parameter
    known_in_order: ClassVar[bool] = False  # list the known keys as declared (a parameter dataclass's order)

    @classmethod
    def known_keys(cls) -> list[str]:
        keys = [f.alias or name for name, f in cls.model_fields.items() if name != cls.selector]
        return keys if cls.known_in_order else sorted(keys)

    @model_validator(mode="before")
    @classmethod
    def _a_table_of_known_keys(cls, data: Any) -> Any:
        if not isinstance(data, Mapping):
            raise PydanticCustomError("not_a_table", "expected a table")
        known = _KNOWN.get(cls)
        if known is None:  # a table's keys are its class's: found once (every run of a study validates them)
            known = _KNOWN[cls] = frozenset(cls.known_keys()) | ({cls.selector} if cls.selector else set())
        for key in data:
            if key not in known:
                raise PydanticCustomError("unknown_key", "unknown key", {"key": key,
                                                                         "known": ", ".join(cls.known_keys())})
        return data


# ---- errors ---------------------------------------------------------------------------------------

def where(loc: Iterable[Any], prefix: str = "", quote: bool = False) -> str:
    """A pydantic location as the document's key: ``a.b[2].c`` (prefix
    first); with ``quote``, a key holding a dot is quoted (``sweep.grid."wind.speed"``)."""
    out = prefix
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif not str(part).startswith("function-"):  # a validator's own name in the location
            part = f'"{part}"' if quote and "." in str(part) else str(part)
            out += ("." if out else "") + part
    return out


_PHRASES = {
    "float_type": "expected a number", "float_parsing": "expected a number", "int_type": "expected an integer",
    "int_from_float": "expected an integer", "finite_number": "expected a finite number",
    "string_type": "expected a string", "bool_type": "expected true or false", "list_type": "expected a list",
    "dict_type": "expected a table", "model_type": "expected a table", "model_attributes_type": "expected a table",
    "not_a_table": "expected a table", "tuple_type": "expected a list",
}


def _phrase(err: Mapping[str, Any]) -> str:
    kind, ctx = err["type"], err.get("ctx") or {}
    if kind in _PHRASES:
        return _PHRASES[kind]
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        bound = ctx.get("gt", ctx.get("ge", ctx.get("lt", ctx.get("le"))))
        if kind == "greater_than" and bound == 0:
            return "must be positive"
        if kind == "greater_than_equal" and bound == 0:
            return "must not be negative"
        words = {"greater_than": "above", "greater_than_equal": "at least", "less_than": "below",
                 "less_than_equal": "at most"}[kind]
        return f"must be {words} {bound:g}" if isinstance(bound, float) else f"must be {words} {bound}"
    if kind in ("too_short", "too_long"):
        low, high = ctx.get("min_length"), ctx.get("max_length")
        if kind == "too_short" and low is not None:
            return f"expected a list of {low} values" if high in (None, low) else f"expected at least {low} values"
        return f"expected at most {high} values"
    if kind == "literal_error":
        return f"expected {ctx.get('expected')}"
    if kind == "missing":
        return "required"
    return err.get("msg", kind)


def scenario_error(exc: ValidationError | Mapping[str, Any], prefix: str = "", quote: bool = False) -> ScenarioError:
    """The first error of ``exc`` (or one error, as ``ValidationError.errors()``
    gives them) as the engine's one line: ``key = value: what was expected``
    (``key: ...`` where the value would say nothing); ``quote``: dotted keys
    quoted, as a study file writes them."""
    err = exc.errors(include_url=False)[0] if isinstance(exc, ValidationError) else exc
    loc = [p for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-"))]
    ctx = err.get("ctx") or {}
    kind = err["type"]
    key_of = lambda parts: where(parts, prefix, quote) or "document"  # noqa: E731
    if kind == "unknown_key":
        return ScenarioError(f"{key_of(loc + [ctx['key']])}: unknown key; known keys: {ctx['known']}")
    if kind == "refused":
        key = key_of(loc + ([ctx["key"]] if ctx.get("key") else []))
        shown = f" = {_shown(ctx['value'])}" if "value" in ctx else ""
        return ScenarioError(f"{key}{shown}: {ctx['message']}")
    if kind == "value_error":  # a domain check of ours (a parameter dataclass, a law) in its own words
        return ScenarioError(f"{key_of(loc)}: {ctx.get('error', err['msg'])}")
    if kind == "missing":
        return ScenarioError(f"{key_of(loc)}: required")
    return ScenarioError(f"{key_of(loc)} = {_shown(err.get('input'))}: {_phrase(err)}")


def _shown(value: Any) -> str:
    """A value as the document gave it, kept to one short line."""
    text = repr(value)
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10 ** 20:
        return f"{str(value)[:12]}... ({len(str(abs(value)))} digits)"
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return text if len(text) <= 200 else text[:197] + "..."


def validate(model: type[BaseModel], data: Any, prefix: str = "", context: Mapping[str, Any] | None = None,
             quote: bool = False):
    """``model`` validated from ``data`` (any mappings and sequences: a
    scenario's read-only views too), or the one-line :class:`ScenarioError`."""
    try:
        return model.model_validate(thawed(data), context=dict(context or {}))
    except ValidationError as exc:
        raise scenario_error(exc, prefix, quote) from None


def thawed(value: Any) -> Any:
    """Plain data of a document: mappings as dicts, tuples as lists (strict
    validation takes nothing else)."""
    if isinstance(value, Mapping):
        return {k: thawed(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [thawed(v) for v in value]
    return value


def json_schema(model: type[BaseModel], title: str, description: str = "") -> dict[str, Any]:
    """The JSON Schema of ``model`` (draft 2020-12), as editors take it (a
    key left out keeps its default, so ``null`` defaults are not shown)."""
    schema = _without_null_defaults(model.model_json_schema(mode="validation"))
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = title
    if description:
        schema["description"] = description
    return schema


def _without_null_defaults(node: Any) -> Any:
    if isinstance(node, dict):
        return {k: _without_null_defaults(v) for k, v in node.items() if not (k == "default" and v is None)}
    if isinstance(node, list):
        return [_without_null_defaults(v) for v in node]
    return node


# ---- choices, lists, parameter dataclasses ---------------------------------------------------------

def one_of(values: Iterable[Any], phrase: str | None = None, type_: type = str):
    """A value among ``values`` (strict ``type_``), refused as ``expected one of a, b``
    (or ``phrase``); the JSON Schema lists them as an ``enum``."""
    values = tuple(values)
    said = phrase or f"expected one of {', '.join(str(v) for v in values)}"

    def check(value: Any) -> Any:
        if isinstance(value, bool) or not isinstance(value, type_) or value not in values:
            raise refuse(said, value=value)
        return value

    kind = {str: "string", int: "integer"}.get(type_, "string")
    return Annotated[type_, BeforeValidator(check), WithJsonSchema({"type": kind, "enum": list(values)})]


def _strings(value: Any) -> Any:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise refuse("expected a list of strings", value=value)
    return value


Strings = Annotated[list[str], BeforeValidator(_strings)]


def _names(value: Any) -> Any:
    from ..files import repeated

    twice = repeated(_strings(value))
    if twice is not None:  # a signal recorded twice: a column twice in the results, and memory for nothing
        raise refuse(f"{twice!r} is given twice; each at most once")
    return value


Names = Annotated[list[str], BeforeValidator(_names)]  # strings, each given once (cosim.files.repeated)


def numbers(n: int, what: str = "values", schema: Mapping[str, Any] | None = None, **constraints):
    """A list of exactly ``n`` numbers (``expected a list of n values``);
    ``schema`` adds to each item's JSON Schema (e.g. its range, not enforced here)."""
    item = Annotated[float, Field(strict=True, allow_inf_nan=False, json_schema_extra=dict(schema or {}) or None,
                                  **constraints)]

    def check(value: Any) -> Any:
        if not isinstance(value, (list, tuple)) or len(value) != n:
            raise refuse(f"expected a list of {n} {what}", value=value)
        return list(value)

    return Annotated[list[item], BeforeValidator(check), Field(min_length=n, max_length=n)]


def _field_schema(metadata: Mapping[str, Any]) -> dict[str, Any]:
    extra: dict[str, Any] = {}
    for key, name in (("min", "minimum"), ("max", "maximum")):
        value = metadata.get(key)
        if isinstance(value, (int, float)) and math.isfinite(value):
            extra[name] = value
    if metadata.get("unit"):
        extra["unit"] = metadata["unit"]
    return extra


class ParameterTable(Table):
    """A table of a frozen parameter dataclass's fields (made by
    :func:`dataclass_table`): every key optional, the keys listed in the
    dataclass's order, its ranges in the JSON Schema; the dataclass itself
    checks the values (its own words) when :meth:`applied`."""

    known_in_order: ClassVar[bool] = True
    dataclass_type: ClassVar[Any] = None

    def applied(self, base: Any = None) -> Any:
        """``base`` (default: the dataclass's defaults) with the given keys
        replaced (:func:`cosim.scenario.parameters.replaced`)."""
        from .parameters import replaced

        base = self.dataclass_type() if base is None else base
        return replaced(base, {name: getattr(self, name) for name in self.model_fields_set})

    @model_validator(mode="after")
    def _in_range(self):
        self.applied()  # the dataclass's own checks (ranges, combinations), raising ValueError in its words
        return self


@functools.lru_cache(maxsize=None)
def dataclass_table(cls, name: str | None = None) -> type[ParameterTable]:
    """A :class:`ParameterTable` for the frozen dataclass ``cls``: a float field
    takes a number, an int field an integer, a bool field true or false, a
    str field a string, a tuple field a list of as many numbers, a nested
    dataclass field its own table. Unit, description and range come from the
    fields' metadata (``unit``, ``description``, ``min``, ``max``) where given."""
    import dataclasses

    from pydantic import create_model

    defaults = cls()
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        value = getattr(defaults, f.name)
        meta = dict(f.metadata)
        text = meta.get("description", "")
        if meta.get("unit"):
            text = f"{text} [{meta['unit']}]" if text else f"[{meta['unit']}]"
        extra = _field_schema(meta)
        bounds = {k: v for k, v in extra.items() if k != "unit"}
        if dataclasses.is_dataclass(value):
            annotation: Any = dataclass_table(type(value))
        elif isinstance(value, bool):
            annotation = Annotated[bool, Field(strict=True)]
        elif isinstance(value, float):
            annotation = Annotated[float, Field(strict=True, allow_inf_nan=False, json_schema_extra=bounds or None)]
        elif isinstance(value, int):
            annotation = Annotated[int, Field(strict=True, json_schema_extra=bounds or None)]
        elif isinstance(value, str):
            annotation = Annotated[str, Field(strict=True)]
        elif isinstance(value, tuple):
            annotation = numbers(len(value), schema=bounds)
        else:
            continue  # not settable from a file
        unit = {"unit": extra["unit"]} if "unit" in extra else None
        # no default in the file's terms: an unset key keeps the dataclass's default (applied())
        fields[f.name] = (annotation, Field(default=None, description=text or None, json_schema_extra=unit))
    model = create_model(name or cls.__name__, __base__=ParameterTable, **fields)
    model.dataclass_type = cls
    return model
