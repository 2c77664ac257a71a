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
_HEAD_WIDTH = {spec.msg_id: _width(spec.head) for spec in MESSAGES}
_GROUP_WIDTH = {spec.msg_id: _width(spec.group) for spec in MESSAGES}
_GROUP_OFFSETS = {spec.msg_id: tuple(_width(spec.group[:i]) for i in range(len(spec.group))) for spec in MESSAGES}


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
            return _build(spec, head, _unpack_variable(spec, payload, count))
    values = _unpack(_struct(spec, count), payload, spec)
    return _build(spec, values, _columns(spec, values, count) if count else [() for _ in spec.group])


def _unpack(st: struct.Struct, payload: bytes, spec: MessageSpec) -> tuple:
    if len(payload) != st.size:
        raise DecodeError(f"{spec.name}: {len(payload)} bytes, expected {st.size}", "bad_length")
    return st.unpack(payload)


def _columns(spec: MessageSpec, values: tuple, count: int) -> list[tuple]:
    """Group values (record-major after the head and count) regrouped as one tuple per field."""
    base = _HEAD_WIDTH[spec.msg_id] + 1
    width = _GROUP_WIDTH[spec.msg_id]
    end = base + width * count
    columns = []
    for f, offset in zip(spec.group, _GROUP_OFFSETS[spec.msg_id], strict=True):
        start = base + offset
        if f.count == 1:
            columns.append(values[start:end:width])
        else:
            columns.append(tuple(zip(*(values[start + k : end : width] for k in range(f.count)), strict=True)))
    return columns


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


def _build(spec: MessageSpec, head: tuple, columns: list[tuple]) -> Message:
    """Validate and assemble; ``head`` holds the head values first (extra trailing values are ignored)."""
    args = []
    i = 0
    for f in spec.head:
        if f.count > 1:
            v = head[i : i + f.count]
            if not math.isfinite(sum(v)):
                raise DecodeError(f"{spec.name}.{f.name}: not finite", "bad_value")
        else:
            v = head[i]
            if f.kind != "int":
                v = _scalar(spec, f, v)
        args.append(v)
        i += f.count
    for f, col in zip(spec.group, columns, strict=True):
        if f.kind == "float":
            total = sum(col) if f.count == 1 else sum(map(sum, col))  # finite float32s cannot overflow
            if not math.isfinite(total):
                raise DecodeError(f"{spec.name}.{f.name}: not finite", "bad_value")
        elif f.kind == "bool":
            if col and max(col) > 1:
                raise DecodeError(f"{spec.name}.{f.name}: not a bool", "bad_value")
            col = tuple(map(bool, col))
        elif f.kind == "enum":
            col = tuple(_scalar(spec, f, v) for v in col)
        args.append(col)
    if columns and len(set(columns[0])) != len(columns[0]):
        raise DecodeError(f"{spec.name}.{spec.group[0].name}: duplicated id", "bad_value")
    return MESSAGE_CLASSES[spec.msg_id](*args)


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
