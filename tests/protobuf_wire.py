"""A protobuf decoder driven by a schema's ``FileDescriptorSet`` (the bytes an MCAP ``protobuf`` schema holds).

The test environment has no ``google.protobuf`` (nor ``mcap-protobuf-support``); this reads the wire format
(varint, 64-bit, length-delimited, 32-bit) and checks every field of a message against its descriptor: the field
number must exist in the message type, its wire type must be that of the declared type, nested messages are
decoded recursively, strings must be UTF-8.  Enough to say "this message decodes with this schema" and to read
its values back; not a general protobuf library (no groups, no maps beyond repeated messages, no extensions).
"""

from __future__ import annotations

import struct

# FieldDescriptorProto.Type -> wire type
_WIRE = {1: 1, 2: 5, 3: 0, 4: 0, 5: 0, 6: 1, 7: 5, 8: 0, 9: 2, 11: 2, 12: 2, 13: 0, 14: 0, 15: 5, 16: 1, 17: 0,
         18: 0}
_TYPE_STRING, _TYPE_MESSAGE, _TYPE_BYTES = 9, 11, 12


def _varint(b: bytes, i: int) -> tuple[int, int]:
    shift = out = 0
    while True:
        if i >= len(b):
            raise ValueError("truncated varint")
        c = b[i]
        out |= (c & 0x7F) << shift
        i += 1
        if c < 0x80:
            return out, i
        shift += 7
        if shift > 63:
            raise ValueError("varint too long")


def fields(b: bytes):
    """Yield ``(field number, wire type, value)``: int for varints, bytes for the others."""
    i = 0
    while i < len(b):
        key, i = _varint(b, i)
        num, wt = key >> 3, key & 7
        if wt == 0:
            v, i = _varint(b, i)
        elif wt == 1:
            v, i = b[i:i + 8], i + 8
        elif wt == 5:
            v, i = b[i:i + 4], i + 4
        elif wt == 2:
            n, i = _varint(b, i)
            v, i = b[i:i + n], i + n
        else:
            raise ValueError(f"wire type {wt} not supported")
        if i > len(b):
            raise ValueError("truncated field")
        yield num, wt, v


def message_types(descriptor_set: bytes) -> dict[str, dict[int, tuple]]:
    """``".pkg.Name"`` -> {field number: (name, type, type_name, repeated)} of every message in the set."""
    out: dict[str, dict[int, tuple]] = {}

    def message(b: bytes, scope: str) -> None:
        name, flds, nested = "", {}, []
        for num, _, v in fields(b):
            if num == 1:
                name = v.decode()
            elif num == 2:  # FieldDescriptorProto
                f = {n: val for n, _, val in fields(v)}
                flds[f[3]] = (f[1].decode(), f[5], f.get(6, b"").decode(), f.get(4) == 3)
            elif num == 3:
                nested.append(v)
        full = f"{scope}.{name}"
        out[full] = flds
        for n in nested:
            message(n, full)

    for num, _, fdp in fields(descriptor_set):
        if num != 1:
            continue
        parts = {n: v for n, _, v in fields(fdp) if n in (2,)}
        pkg = parts.get(2, b"").decode()
        for n, _, v in fields(fdp):
            if n == 4:
                message(v, "." + pkg if pkg else "")
    return out


def _scalar(typ: int, wt: int, v):
    if wt == 1:
        return struct.unpack("<d" if typ == 1 else ("<q" if typ in (16, 3) else "<Q"), v)[0]
    if wt == 5:
        return struct.unpack("<f" if typ == 2 else ("<i" if typ == 15 else "<I"), v)[0]
    if typ == 8:
        return bool(v)
    return v


def decode(types: dict, type_name: str, b: bytes) -> dict:
    """The message ``b`` of ``type_name`` as a dict (repeated fields as lists); ValueError where it does not
    fit the schema."""
    desc = types[type_name]
    out: dict = {}
    for num, wt, v in fields(b):
        if num not in desc:
            raise ValueError(f"{type_name}: field {num} not in the schema")
        name, typ, tname, repeated = desc[num]
        if wt == 2 and _WIRE.get(typ) != 2 and repeated:  # packed repeated scalars
            raise ValueError(f"{type_name}.{name}: packed scalars not expected here")
        if _WIRE.get(typ) != wt:
            raise ValueError(f"{type_name}.{name}: wire type {wt}, schema type {typ}")
        if typ == _TYPE_MESSAGE:
            val = decode(types, tname, v)
        elif typ == _TYPE_STRING:
            val = v.decode("utf-8")
        elif typ == _TYPE_BYTES:
            val = v
        else:
            val = _scalar(typ, wt, v)
        if repeated:
            out.setdefault(name, []).append(val)
        else:
            out[name] = val
    return out
