"""A ULog file written by hand, for the tests that read one (PX4's format:
https://docs.px4.io/main/en/dev_log/ulog_file_format.html): the header, the
flag bits ('B'), one format per topic ('F': ``uint64_t timestamp`` in
microseconds, then doubles, an array field as ``double[k] name``), the
subscriptions ('A') and the data messages ('D'), all little-endian, topics
one after the other (a reader sorts nothing: each topic's samples are in
time order)."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

__all__ = ["write_ulog"]


def _message(kind: bytes, body: bytes) -> bytes:
    return struct.pack("<HB", len(body), kind[0]) + body


def write_ulog(path: Path, topics: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]) -> Path:
    """``topics``: name -> (timestamps in us, field -> values: one a sample,
    or samples x k for an array field ``field[0..k-1]``)."""
    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0)
    out += _message(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    shaped = {name: (np.asarray(t), {f: np.asarray(v, float).reshape(len(t), -1) for f, v in fields.items()})
              for name, (t, fields) in topics.items()}
    for name, (_, fields) in shaped.items():
        declared = "".join(f"double {f};" if v.shape[1] == 1 and np.ndim(topics[name][1][f]) == 1
                           else f"double[{v.shape[1]}] {f};" for f, v in fields.items())
        out += _message(b"F", f"{name}:uint64_t timestamp;{declared}".encode())
    for msg_id, name in enumerate(shaped):
        out += _message(b"A", struct.pack("<BH", 0, msg_id) + name.encode())
    for msg_id, (times_us, fields) in enumerate(shaped.values()):
        data = np.hstack(list(fields.values()))
        for k, t in enumerate(times_us):
            out += _message(b"D", struct.pack(f"<HQ{data.shape[1]}d", msg_id, int(t), *data[k]))
    path.write_bytes(out)
    return path
