"""Hypothesis strategies for every protocol message, derived from the schema.

For property tests of this package and of code built on it (simulated boards,
links). Imports hypothesis, a test-only dependency: production code never
imports this module. Floats are drawn as finite float32 values so that
round trips are exact.
"""

from __future__ import annotations

from hypothesis import strategies as st

from .messages import MESSAGE_CLASSES, Message
from .schema import MAX_NAME, MESSAGES, Field, MessageSpec

_F32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
_NAME = st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E), min_size=1, max_size=MAX_NAME)


def field_values(f: Field) -> st.SearchStrategy:
    """Valid values of one field (one record's worth for a group field)."""
    if f.kind == "float":
        return _F32 if f.count == 1 else st.tuples(*[_F32] * f.count)
    if f.kind == "bool":
        return st.booleans()
    if f.kind == "enum":
        return st.sampled_from(list(f.enum))
    if f.kind == "str":
        return _NAME
    return st.integers(0, (1 << 8 * f.size) - 1)


@st.composite
def _message(draw, spec: MessageSpec) -> Message:
    values = {f.name: draw(field_values(f)) for f in spec.head}
    if spec.group_max:
        key, rest = spec.group[0], spec.group[1:]
        records = draw(st.lists(st.tuples(field_values(key), *map(field_values, rest)),
                                max_size=spec.group_max, unique_by=lambda r: r[0]))
        for i, f in enumerate(spec.group):
            values[f.name] = tuple(r[i] for r in records)
    return MESSAGE_CLASSES[spec.msg_id](**values)


def message_of(name: str) -> st.SearchStrategy:
    """Valid messages of the named type (e.g. "JOINT_STATE")."""
    return _message(next(spec for spec in MESSAGES if spec.name == name))


def messages() -> st.SearchStrategy:
    """Valid messages of any type."""
    return st.one_of([_message(spec) for spec in MESSAGES])
