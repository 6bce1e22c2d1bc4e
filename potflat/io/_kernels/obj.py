"""The Wavefront OBJ tokenizer: the file's bytes (``uint8``) are read in two passes over
ranges of whole lines: :func:`obj_count` sizes the output, :func:`obj_fill` parses into
preallocated arrays (the ranges of a file side by side, in threads).

Arrays in, arrays out, no I/O (the caller reads the file).
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf

#: The order of the counts of :func:`obj_count` (and of the running offsets of :func:`obj_fill`).
OBJ_VERTICES, OBJ_TEXCOORDS, OBJ_FACES, OBJ_CORNERS, OBJ_USEMTL, OBJ_MTLLIB, OBJ_LINES = range(7)
#: Marker for an index that can never be valid (``0`` in an OBJ face, or malformed).
BAD_INDEX = -(2**62)


@leaf
def _is_space(c):
    return c == 32 or c == 9 or c == 13 or c == 11 or c == 12


@leaf
def _skip_spaces(buf, i, n):
    while i < n and _is_space(buf[np.uint64(i)]):
        i += 1
    return i


@leaf
def _skip_line(buf, i, n):
    while i < n and buf[np.uint64(i)] != 10:
        i += 1
    return i


@leaf
def _token_end(buf, i, n):
    while i < n and buf[np.uint64(i)] != 10 and not _is_space(buf[np.uint64(i)]):
        i += 1
    return i


@leaf
def _keyword(buf, i, n):
    """Code of the OBJ keyword at ``i``: 1 v, 2 vt, 3 f, 4 usemtl, 5 mtllib, 0 other."""
    j = _token_end(buf, i, n)
    k = j - i
    if k == 1 and buf[i] == 118:  # v
        return 1, j
    if k == 1 and buf[i] == 102:  # f
        return 3, j
    if k == 2 and buf[i] == 118 and buf[i + 1] == 116:  # vt
        return 2, j
    if k == 6 and buf[i] == 117 and buf[i + 1] == 115 and buf[i + 2] == 101 and buf[i + 3] == 109:
        return 4, j  # usem(tl)
    if k == 6 and buf[i] == 109 and buf[i + 1] == 116 and buf[i + 2] == 108 and buf[i + 3] == 108:
        return 5, j  # mtll(ib)
    return 0, j


@leaf
def _parse_float(buf, i, n):
    """Parse a decimal float at ``i``; returns (value, end, ok). ``nan``/``inf`` are parsed."""
    neg = False
    if i < n and (buf[i] == 45 or buf[i] == 43):
        neg = buf[i] == 45
        i += 1
    if i < n and (buf[i] | 32) == 110:  # nan
        return np.nan, _token_end(buf, i, n), True
    if i < n and (buf[i] | 32) == 105:  # inf
        return (-np.inf if neg else np.inf), _token_end(buf, i, n), True
    mant = 0
    ndig = 0
    exp10 = 0
    seen = False
    while i < n and 48 <= buf[np.uint64(i)] <= 57:
        seen = True
        if ndig < 18:
            mant = mant * 10 + (buf[np.uint64(i)] - 48)
            if mant > 0:
                ndig += 1
        else:
            exp10 += 1
        i += 1
    if i < n and buf[i] == 46:
        i += 1
        while i < n and 48 <= buf[np.uint64(i)] <= 57:
            seen = True
            if ndig < 18:
                mant = mant * 10 + (buf[np.uint64(i)] - 48)
                if mant > 0:
                    ndig += 1
                exp10 -= 1
            i += 1
    if not seen:
        return 0.0, i, False
    if i < n and (buf[i] | 32) == 101:  # e / E
        i += 1
        eneg = False
        if i < n and (buf[i] == 45 or buf[i] == 43):
            eneg = buf[i] == 45
            i += 1
        e = 0
        eseen = False
        while i < n and 48 <= buf[i] <= 57:
            eseen = True
            if e < 100000:
                e = e * 10 + (buf[i] - 48)
            i += 1
        if not eseen:
            return 0.0, i, False
        exp10 += -e if eneg else e
    val = float(mant)
    if mant == 0:
        val = 0.0
    elif exp10 > 0:
        val = val * 10.0 ** exp10
    elif exp10 < 0:
        if exp10 < -300:
            val = (val / 10.0 ** 300) / 10.0 ** (-exp10 - 300)
        else:
            val = val / 10.0 ** (-exp10)
    return (-val if neg else val), i, True


@leaf
def _parse_int(buf, i, n):
    """Parse a signed integer at ``i``; returns (value, end, ok)."""
    neg = False
    if i < n and (buf[i] == 45 or buf[i] == 43):
        neg = buf[i] == 45
        i += 1
    v = 0
    seen = False
    while i < n and 48 <= buf[np.uint64(i)] <= 57:
        if v < 10**15:
            v = v * 10 + (buf[np.uint64(i)] - 48)
        seen = True
        i += 1
    return (-v if neg else v), i, seen


@leaf
def obj_count(buf, start, stop):
    """Count the records of the lines of an OBJ file in ``buf[start:stop]``.

    Parameters
    ----------
    buf : (nbytes,) uint8
        The file's content.
    start, stop : int
        A range of whole lines: ``start`` is 0 or follows a newline, ``stop`` follows a
        newline or is the end of the file.

    Returns
    -------
    counts : (7,) int64
        Vertices, texture coordinates, faces, face corners, ``usemtl`` lines, ``mtllib`` lines
        and lines (the ``OBJ_*`` indices).
    """
    n = np.int64(stop)
    counts = np.zeros(7, np.int64)
    i = np.int64(start)
    while i < n:
        counts[OBJ_LINES] += 1
        i = _skip_spaces(buf, i, n)
        if i < n and buf[i] != 10 and buf[i] != 35:
            kw, i = _keyword(buf, i, n)
            if kw == 1:
                counts[OBJ_VERTICES] += 1
            elif kw == 2:
                counts[OBJ_TEXCOORDS] += 1
            elif kw == 3:
                counts[OBJ_FACES] += 1
                while True:
                    i = _skip_spaces(buf, i, n)
                    if i >= n or buf[i] == 10 or buf[i] == 35:
                        break
                    counts[OBJ_CORNERS] += 1
                    i = _token_end(buf, i, n)
            elif kw == 4:
                counts[OBJ_USEMTL] += 1
            elif kw == 5:
                counts[OBJ_MTLLIB] += 1
        i = _skip_line(buf, i, n) + 1
    return counts


@leaf
def obj_fill(buf, start, stop, before, V, vcols, VT, corner_v, corner_vt, face_ptr, use_spans, lib_spans):
    """Parse the lines of an OBJ file in ``buf[start:stop]`` into arrays sized by
    :func:`obj_count`, at the rows after the records of the lines before them.

    Ranges of one file can be parsed in any order, also at the same time (each writes its
    own rows; serial, without the GIL).

    Parameters
    ----------
    buf : (nbytes,) uint8
        The file's content.
    start, stop : int
        A range of whole lines (as in :func:`obj_count`).
    before : (7,) int64
        :func:`obj_count` of ``buf[:start]``: where the range's rows start, its first line's
        number - 1, and the vertex and texture counts that relative (negative) indices count
        back from.
    V : (nv, 6) float64
        Output (filled with NaN): up to six numbers per ``v`` line (x y z and optional r g b).
    vcols : (nv,) int64
        Output: how many numbers each ``v`` line had.
    VT : (nvt, 2) float64
        Output (filled with 0): the first two numbers of each ``vt`` line.
    corner_v, corner_vt : (nc,) int64
        Output: 0-based vertex and texture indices of each face corner; relative (negative)
        indices resolved; ``-1`` = no texture index; :data:`BAD_INDEX` = malformed or zero index.
    face_ptr : (nf + 1,) int64
        Output (``face_ptr[0] = 0``): corners of face ``k`` are ``face_ptr[k]:face_ptr[k + 1]``.
    use_spans : (nuse, 3) int64
        Output: byte span of each ``usemtl`` line's argument and the index of the next face.
    lib_spans : (nlib, 2) int64
        Output: byte span of each ``mtllib`` line's argument.

    Returns
    -------
    bad_line : int
        1-based number (in the file) of the range's first line with an unparsable number, 0 if none.
    """
    n = np.int64(stop)
    iv = before[OBJ_VERTICES]
    ivt = before[OBJ_TEXCOORDS]
    jf = before[OBJ_FACES]
    jc = before[OBJ_CORNERS]
    ju = before[OBJ_USEMTL]
    jl = before[OBJ_MTLLIB]
    line = before[OBJ_LINES]
    bad_line = 0
    i = np.int64(start)
    while i < n:
        line += 1
        i = _skip_spaces(buf, i, n)
        if i < n and buf[i] != 10 and buf[i] != 35:
            kw, i = _keyword(buf, i, n)
            if kw == 1 or kw == 2:
                k = 0
                while True:
                    i = _skip_spaces(buf, i, n)
                    if i >= n or buf[i] == 10 or buf[i] == 35:
                        break
                    val, i, ok = _parse_float(buf, i, n)
                    if not ok or (i < n and buf[i] != 10 and not _is_space(buf[i])):
                        if bad_line == 0:
                            bad_line = line
                        i = _token_end(buf, i, n)
                        val = np.nan
                    if kw == 1 and k < 6:
                        V[iv, k] = val
                    elif kw == 2 and k < 2:
                        VT[ivt, k] = val
                    k += 1
                if kw == 1:
                    vcols[iv] = k
                    iv += 1
                else:
                    ivt += 1
            elif kw == 3:
                while True:
                    i = _skip_spaces(buf, i, n)
                    if i >= n or buf[i] == 10 or buf[i] == 35:
                        break
                    end = _token_end(buf, i, n)
                    a, i, ok = _parse_int(buf, i, end)
                    if not ok or a == 0:
                        cv = BAD_INDEX
                    elif a > 0:
                        cv = a - 1
                    else:
                        cv = iv + a
                        if cv < 0:
                            cv = BAD_INDEX
                    ct = -1
                    if i < end and buf[i] == 47:  # '/'
                        i += 1
                        if i < end and buf[i] != 47:
                            t, i, ok = _parse_int(buf, i, end)
                            if not ok or t == 0:
                                ct = BAD_INDEX
                            elif t > 0:
                                ct = t - 1
                            else:
                                ct = ivt + t
                                if ct < 0:
                                    ct = BAD_INDEX
                    i = end
                    corner_v[jc] = cv
                    corner_vt[jc] = ct
                    jc += 1
                jf += 1
                face_ptr[jf] = jc
            elif kw == 4 or kw == 5:
                i = _skip_spaces(buf, i, n)
                e = _skip_line(buf, i, n)
                while e > i and _is_space(buf[e - 1]):
                    e -= 1
                if kw == 4:
                    use_spans[ju, 0] = i
                    use_spans[ju, 1] = e
                    use_spans[ju, 2] = jf
                    ju += 1
                else:
                    lib_spans[jl, 0] = i
                    lib_spans[jl, 1] = e
                    jl += 1
        i = _skip_line(buf, i, n) + 1
    return bad_line
