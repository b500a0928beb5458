"""LZF, the compression of PCL's ``binary_compressed`` PCD: a pure-Python decoder and a literal-run encoder."""

from __future__ import annotations


def lzf_decompress(data: bytes, size: int) -> bytes:
    """Decompress an LZF stream (liblzf's format, the one PCL's ``binary_compressed`` uses) to ``size`` bytes.

    Tokens: a control byte below 32 starts a literal run of ``ctrl + 1`` bytes; otherwise the top three
    bits are the back-reference length - 2 (7: one more length byte follows) and the low five bits with the
    next byte the distance - 1. Overlapping references (runs: the NaN stretches of a depth image) are
    copied a period at a time. Raises ``ValueError`` on a corrupt stream.
    """
    src = memoryview(bytes(data))
    buf = bytearray(size)
    ip = op = 0
    n = len(src)
    try:
        while ip < n:
            ctrl = src[ip]
            ip += 1
            if ctrl < 32:
                ln = ctrl + 1
                if op + ln > size or ip + ln > n:
                    raise ValueError("LZF literal run overflows")
                buf[op : op + ln] = src[ip : ip + ln]
                ip += ln
                op += ln
                continue
            ln = ctrl >> 5
            if ln == 7:
                ln += src[ip]
                ip += 1
            ref = op - ((ctrl & 0x1F) << 8) - src[ip] - 1
            ip += 1
            ln += 2
            if ref < 0 or op + ln > size:
                raise ValueError("LZF back-reference out of range")
            dist = op - ref
            if dist >= ln:
                buf[op : op + ln] = buf[ref : ref + ln]
            else:  # the reference overlaps what it writes: repeat its period
                period = bytes(buf[ref:op])
                buf[op : op + ln] = (period * (ln // dist + 1))[:ln]
            op += ln
    except IndexError:
        raise ValueError("LZF stream ends inside a token") from None
    if op != size:
        raise ValueError(f"LZF stream decompresses to {op} bytes, the header says {size}")
    return bytes(buf)


def lzf_literal(data: bytes) -> bytes:
    """``data`` as a valid LZF stream of literal runs only (32 bytes per run, 1/32 larger than ``data``).

    What :func:`write_pcd` puts in a ``binary_compressed`` file: liblzf, PCL and :func:`lzf_decompress`
    read it. No back-references are searched for (a pure-Python matcher would take seconds per frame);
    the encoding exists for files that must be ``binary_compressed``, not to save space.
    """
    raw = bytes(data)
    return b"".join(bytes((len(raw[i : i + 32]) - 1,)) + raw[i : i + 32] for i in range(0, len(raw), 32))
