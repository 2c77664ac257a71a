"""Payload codec: message dataclass <-> payload bytes, driven by the schema.

Decoding is strict: a payload decodes only if its size matches its record
count exactly, the count is within the schema's limit, every float is finite,
enums and bools hold defined values, ids in a group are unique and names are
printable ASCII. Anything else raises DecodeError with kind ``bad_length`` or
``bad_value``. Encoding applies the same rules and raises ProtocolError naming
the field.
"""

from __future__ import annotations

import math
import operator
import struct
from dataclasses import dataclass
from itertools import chain

from .errors import DecodeError, ProtocolError
from .messages import MESSAGE_CLASSES, Message
from .schema import MAX_NAME, MESSAGES, Field, MessageSpec

_NAME_CHARS = frozenset(range(0x20, 0x7F))


def _codes(fs: tuple[Field, ...]) -> str:
    return "".join(f"{f.count}{f.code}" if f.count > 1 else f.code for f in fs)


def _width(fs: tuple[Field, ...]) -> int:
    """Number of struct values the fields unpack to."""
    return sum(f.count for f in fs)


def _structs(spec: MessageSpec) -> tuple[struct.Struct, ...]:
    """One Struct per record count (just count 0 for records of variable size)."""
    head = "<" + _codes(spec.head) + ("B" if spec.group_max else "")
    counts = range(spec.group_max + 1) if spec.group_max and not spec.variable_records else range(1)
    return tuple(struct.Struct(head + _codes(spec.group) * n) for n in counts)


# Built once from the schema: constant tables, not state.
_STRUCTS = {spec.msg_id: _structs(spec) for spec in MESSAGES}


def _struct(spec: MessageSpec, count: int) -> struct.Struct:
    return _STRUCTS[spec.msg_id][count]


def encode_payload(msg: Message) -> bytes:
    """Payload bytes of a message; ProtocolError naming the field if a value is out of range."""
    spec = msg.spec
    values = _head_values(msg, spec)
    columns = [getattr(msg, f.name) for f in spec.group]
    count = _check_columns(msg, spec, columns) if spec.group_max else 0
    _check_values(msg, spec, columns)
    if spec.variable_records:
        return _pack(_struct(spec, 0), [*values, count], msg) + _pack_variable(msg, spec, columns)
    if spec.group_max:
        values.append(count)
        if all(f.count == 1 for f in spec.group):
            values.extend(chain.from_iterable(zip(*columns, strict=True)))
        else:
            for row in zip(*columns, strict=True):
                for f, v in zip(spec.group, row, strict=True):
                    if f.count > 1:
                        values.extend(v)
                    else:
                        values.append(v)
    return _pack(_struct(spec, count), values, msg)


def _head_values(msg: Message, spec: MessageSpec) -> list:
    values = []
    for f in spec.head:
        v = getattr(msg, f.name)
        if f.count > 1:
            if len(v) != f.count:
                raise ProtocolError(f"{spec.name}.{f.name}: expected {f.count} values, got {len(v)}")
            values.extend(v)
        else:
            values.append(v)
    return values


def _check_columns(msg: Message, spec: MessageSpec, columns: list) -> int:
    count = len(columns[0])
    for f, col in zip(spec.group, columns, strict=True):
        if len(col) != count:
            raise ProtocolError(f"{spec.name}.{f.name}: {len(col)} entries, but {spec.group[0].name} has {count}")
        if f.count > 1 and any(len(rec) != f.count for rec in col):
            raise ProtocolError(f"{spec.name}.{f.name}: every entry needs {f.count} values")
    if count > spec.group_max:
        raise ProtocolError(f"{spec.name}: {count} records, at most {spec.group_max} per message")
    if len(set(columns[0])) != count:
        raise ProtocolError(f"{spec.name}.{spec.group[0].name}: duplicated id in {tuple(columns[0])}")
    return count


def _check_values(msg: Message, spec: MessageSpec, columns: list) -> None:
    """Finite floats, defined enum and bool values: the rules the decoder enforces."""
    for f in spec.head:
        if f.kind == "float":
            v = getattr(msg, f.name)
            _require_finite(msg, v if f.count > 1 else (v,))
        elif f.kind in ("enum", "bool"):
            _require_allowed(spec, f, (getattr(msg, f.name),))
    for f, col in zip(spec.group, columns, strict=True):
        if f.kind == "float":
            _require_finite(msg, col if f.count == 1 else [x for rec in col for x in rec])
        elif f.kind in ("enum", "bool"):
            _require_allowed(spec, f, col)


def _require_finite(msg: Message, values) -> None:
    try:
        total = sum(map(float, values))  # finite float32 values cannot overflow a double sum
    except (TypeError, ValueError):
        _explain(msg)
    if not math.isfinite(total):
        _explain(msg)


def _require_allowed(spec: MessageSpec, f: Field, values) -> None:
    allowed = {0, 1} if f.kind == "bool" else {int(m) for m in f.enum}
    for v in values:
        if v not in allowed:
            raise ProtocolError(f"{spec.name}.{f.name}: {v!r} is not one of {sorted(allowed)}")


def _pack(st: struct.Struct, values: list, msg: Message) -> bytes:
    try:
        return st.pack(*values)
    except (struct.error, OverflowError, TypeError):
        _explain(msg)
        raise


def _pack_variable(msg: Message, spec: MessageSpec, columns: list) -> bytes:
    """Records holding a str16: packed one field at a time."""
    out = bytearray()
    for row in zip(*columns, strict=True):
        for f, v in zip(spec.group, row, strict=True):
            if f.kind == "str":
                raw = _name_bytes(spec, f, v)
                out.append(len(raw))
                out += raw
            else:
                out += _pack(struct.Struct("<" + _codes((f,))), [*v] if f.count > 1 else [v], msg)
    return bytes(out)


def _name_bytes(spec: MessageSpec, f: Field, name: object) -> bytes:
    if not isinstance(name, str) or not 1 <= len(name) <= MAX_NAME or not set(map(ord, name)) <= _NAME_CHARS:
        raise ProtocolError(f"{spec.name}.{f.name}: {name!r} is not 1..{MAX_NAME} printable ASCII characters")
    return name.encode("ascii")


def _explain(msg: Message) -> None:
    """Find the field a failed pack tripped on and raise ProtocolError naming it."""
    spec = msg.spec
    for f in (*spec.head, *spec.group):
        values = getattr(msg, f.name)
        items = values if f in spec.group else (values,)
        for i, item in enumerate(items):
            for v in item if f.count > 1 else (item,):
                where = f"{spec.name}.{f.name}" + (f"[{i}]" if f in spec.group else "")
                _check_scalar(where, f, v)
    raise ProtocolError(f"{spec.name}: values do not fit the wire layout")


def _check_scalar(where: str, f: Field, v: object) -> None:
    if f.kind == "str":
        return
    if f.code == "f":
        try:
            struct.pack("<f", v)
        except (struct.error, TypeError):
            raise ProtocolError(f"{where}: expected a number, got {v!r}") from None
        except OverflowError:
            raise ProtocolError(f"{where}: {v!r} is out of float32 range") from None
        if not math.isfinite(v):
            raise ProtocolError(f"{where}: {v!r} is not finite")
        return
    top = (1 << 8 * struct.calcsize(f.code)) - 1
    try:
        ok = 0 <= operator.index(v) <= top
    except TypeError:
        ok = False
    if not ok:
        raise ProtocolError(f"{where}: {v!r} is not an integer in 0..{top}")


@dataclass(frozen=True)
class _Plan:
    """How to turn the struct values of a fixed-record message into dataclass arguments."""

    structs: tuple[struct.Struct, ...]  # by record count
    head_width: int
    head_plain: bool  # every head field is one int or float: the head arguments are values[:head_width]
    group_width: int
    columns: tuple[tuple[Field, int], ...]  # group field, offset of its first value in a record
    has_float: bool


def _plan(spec: MessageSpec) -> _Plan:
    offsets = [_width(spec.group[:i]) for i in range(len(spec.group))]
    return _Plan(
        _STRUCTS[spec.msg_id], _width(spec.head), all(f.count == 1 and f.kind in ("int", "float") for f in spec.head),
        _width(spec.group), tuple(zip(spec.group, offsets, strict=True)),
        any(f.kind == "float" for f in (*spec.head, *spec.group)),
    )


_PLANS = {spec.msg_id: _plan(spec) for spec in MESSAGES if not spec.variable_records}


def decode_payload(spec: MessageSpec, payload: bytes) -> Message:
    """The message a payload holds; DecodeError(kind='bad_length' | 'bad_value') if it is malformed."""
    count = 0
    if spec.group_max:
        if len(payload) < spec.fixed_size:
            raise DecodeError(f"{spec.name}: {len(payload)} bytes, need at least {spec.fixed_size}", "bad_length")
        count = payload[spec.fixed_size - 1]
        if count > spec.group_max:
            raise DecodeError(f"{spec.name}: {count} records, limit {spec.group_max}", "bad_length")
        if spec.variable_records:
            head = _unpack(_struct(spec, 0), payload[: spec.fixed_size], spec)
            columns = [_column(spec, f, col) for f, col in zip(spec.group, _unpack_variable(spec, payload, count),
                                                               strict=True)]
            return _assemble(spec, _head_args(spec, head), columns, count)
    plan = _PLANS[spec.msg_id]
    values = _unpack(plan.structs[count], payload, spec)
    # Integers are bounded, so the sum is finite exactly when every float is.
    if plan.has_float and not math.isfinite(sum(values)):
        raise DecodeError(f"{spec.name}: a float is not finite", "bad_value")
    args = list(values[: plan.head_width]) if plan.head_plain else _head_args(spec, values)
    if not spec.group_max:
        return MESSAGE_CLASSES[spec.msg_id](*args)
    base = plan.head_width + 1
    width = plan.group_width
    end = base + width * count
    columns = []
    for f, offset in plan.columns:
        start = base + offset
        if f.count == 1:
            col = values[start:end:width]
        else:
            col = tuple(zip(*(values[start + k : end : width] for k in range(f.count)), strict=True))
        columns.append(col if f.kind in ("int", "float") else _column(spec, f, col))
    return _assemble(spec, args, columns, count)


def _unpack(st: struct.Struct, payload: bytes, spec: MessageSpec) -> tuple:
    if len(payload) != st.size:
        raise DecodeError(f"{spec.name}: {len(payload)} bytes, expected {st.size}", "bad_length")
    return st.unpack(payload)


def _unpack_variable(spec: MessageSpec, payload: bytes, count: int) -> list[tuple]:
    pos = spec.fixed_size
    rows = []
    for _ in range(count):
        row = []
        for f in spec.group:
            if f.kind == "str":
                if pos >= len(payload):
                    raise DecodeError(f"{spec.name}.{f.name}: payload ends inside a record", "bad_length")
                n = payload[pos]
                raw = payload[pos + 1 : pos + 1 + n]
                if len(raw) != n:
                    raise DecodeError(f"{spec.name}.{f.name}: payload ends inside a name", "bad_length")
                if not 1 <= n <= MAX_NAME or not set(raw) <= _NAME_CHARS:
                    raise DecodeError(f"{spec.name}.{f.name}: not 1..{MAX_NAME} printable ASCII", "bad_value")
                row.append(raw.decode("ascii"))
                pos += 1 + n
            else:
                if pos + f.size > len(payload):
                    raise DecodeError(f"{spec.name}.{f.name}: payload ends inside a record", "bad_length")
                vals = struct.unpack_from("<" + _codes((f,)), payload, pos)
                row.append(vals if f.count > 1 else vals[0])
                pos += f.size
        rows.append(row)
    if pos != len(payload):
        raise DecodeError(f"{spec.name}: {len(payload) - pos} bytes after the last record", "bad_length")
    return [tuple(col) for col in zip(*rows, strict=True)] if rows else [() for _ in spec.group]


def _head_args(spec: MessageSpec, values: tuple) -> list:
    args = []
    i = 0
    for f in spec.head:
        if f.count > 1:
            v = values[i : i + f.count]
            if not math.isfinite(sum(v)):
                raise DecodeError(f"{spec.name}.{f.name}: not finite", "bad_value")
        else:
            v = values[i] if f.kind == "int" else _scalar(spec, f, values[i])
        args.append(v)
        i += f.count
    return args


def _assemble(spec: MessageSpec, args: list, columns: list[tuple], count: int) -> Message:
    if len(set(columns[0])) != count:
        raise DecodeError(f"{spec.name}.{spec.group[0].name}: duplicated id", "bad_value")
    return MESSAGE_CLASSES[spec.msg_id](*args, *columns)


def _column(spec: MessageSpec, f: Field, col: tuple) -> tuple:
    """Validate and convert one group column (floats already known finite for fixed records)."""
    if f.kind == "float":
        total = sum(col) if f.count == 1 else sum(map(sum, col))
        if not math.isfinite(total):
            raise DecodeError(f"{spec.name}.{f.name}: not finite", "bad_value")
    elif f.kind == "bool":
        if col and max(col) > 1:
            raise DecodeError(f"{spec.name}.{f.name}: not a bool", "bad_value")
        return tuple(map(bool, col))
    elif f.kind == "enum":
        return tuple(_scalar(spec, f, v) for v in col)
    return col


def _scalar(spec: MessageSpec, f: Field, v):
    if f.kind == "float":
        if not math.isfinite(v):
            raise DecodeError(f"{spec.name}.{f.name}: not finite", "bad_value")
    elif f.kind == "enum":
        try:
            return f.enum(v)
        except ValueError:
            raise DecodeError(f"{spec.name}.{f.name}: {v} is not a {f.wire}", "bad_value") from None
    elif f.kind == "bool":
        if v > 1:
            raise DecodeError(f"{spec.name}.{f.name}: {v} is not a bool", "bad_value")
        return v == 1
    return v
