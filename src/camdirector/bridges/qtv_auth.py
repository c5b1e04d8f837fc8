"""The answer to a passworded QTV source (mvdsv's qtv_password), as ezQuake gives it.

A client with a password offers its methods in its request ("AUTH: MD4", "AUTH: CCITT",
"AUTH: PLAIN": ezQuake's, less SHA3_512, whose Keccak variant in mvdsv's sha3.c we do not
reproduce). mvdsv (src/sv_demo_qtv.c, SV_MVD_RunPendingConnections) takes the strongest it knows;
for MD4 or CCITT it answers "AUTH: method" and "CHALLENGE: text" with no BEGIN and waits for a new
request on the same connection carrying "AUTH: method" and "PASSWORD: answer"; for PLAIN the
answer is the password itself. The answers (ezQuake src/cl_demo.c, the QTV request's auth):
- MD4: the MD4 digest of challenge + password as four little-endian 32-bit words, each in
  upper-case hex without leading zeros ("%X%X%X%X"; Com_BlockFullChecksum is plain MD4, RFC 1320);
- CCITT: Quake's CRC (CRC-16/CCITT, initial value 0xFFFF, nothing xored out; crc.c) of
  challenge + password, as "0x%X" (mvdsv reads it with Q_atoi, which takes hex).
A wrong password gets "PERROR: Bad password."; qtv.py says so and the cast stops.
"""

from __future__ import annotations

import binascii
import struct

METHODS = ("MD4", "CCITT", "PLAIN")  # offered, strongest first

_MASK = 0xFFFFFFFF
_ROUND2 = (0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15)
_ROUND3 = (0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15)


def _rotl(x: int, n: int) -> int:
    return ((x << n) | (x >> (32 - n))) & _MASK


def md4(data: bytes) -> bytes:
    """The MD4 digest of data (RFC 1320): hashlib's OpenSSL no longer offers it."""
    message = data + b"\x80" + b"\x00" * ((55 - len(data)) % 64) + struct.pack("<Q", 8 * len(data))
    h = [0x67452301, 0xEFCDAB89, 0x98BADCFE, 0x10325476]
    for block in range(0, len(message), 64):
        x = struct.unpack("<16I", message[block : block + 64])
        a, b, c, d = h
        for i in range(16):
            a, b, c, d = d, _rotl((a + ((b & c) | (~b & d)) + x[i]) & _MASK, (3, 7, 11, 19)[i % 4]), b, c
        for i in range(16):
            k = _ROUND2[i]
            a, b, c, d = d, _rotl((a + ((b & c) | (b & d) | (c & d)) + x[k] + 0x5A827999) & _MASK, (3, 5, 9, 13)[i % 4]), b, c
        for i in range(16):
            k = _ROUND3[i]
            a, b, c, d = d, _rotl((a + (b ^ c ^ d) + x[k] + 0x6ED9EBA1) & _MASK, (3, 9, 11, 15)[i % 4]), b, c
        h = [(v + w) & _MASK for v, w in zip(h, (a, b, c, d))]
    return struct.pack("<4I", *h)


def answer(method: str, challenge: str, password: str) -> str:
    """The PASSWORD line's value for the source's method and challenge (module docstring);
    ValueError for a method this client does not speak."""
    text = (challenge + password).encode("latin-1")
    if method == "MD4":
        return "".join(f"{word:X}" for word in struct.unpack("<4I", md4(text)))
    if method == "CCITT":
        return f"0x{binascii.crc_hqx(text, 0xFFFF):X}"
    if method == "PLAIN":
        return password
    raise ValueError(f"the source asks for AUTH {method}, which this client does not speak ({', '.join(METHODS)})")
