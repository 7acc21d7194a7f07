"""Reads glyphs from an X11 PCF bitmap font (for scripts/make_font.py).

`python3 scripts/pcf_font.py FONT.pcf.gz TEXT` prints TEXT's glyphs."""
import gzip, struct, sys
def load(path):
    d = gzip.open(path).read()
    assert d[:4] == b'\x01fcp'
    n = struct.unpack('<I', d[4:8])[0]
    tables = {}
    for i in range(n):
        t, fmt, size, off = struct.unpack('<IIII', d[8+16*i:24+16*i])
        tables[t] = (fmt, off)
    def fmt_at(off):
        f = struct.unpack('<I', d[off:off+4])[0]
        return f, ('>' if f & 4 else '<')
    # metrics
    f, e = fmt_at(tables[4][1]); off = tables[4][1] + 4
    metrics = []
    if f & 0x100:
        cnt = struct.unpack(e+'H', d[off:off+2])[0]; off += 2
        for i in range(cnt):
            l, r, w, a, de = [b - 0x80 for b in d[off:off+5]]; off += 5
            metrics.append((l, r, w, a, de))
    else:
        cnt = struct.unpack(e+'I', d[off:off+4])[0]; off += 4
        for i in range(cnt):
            l, r, w, a, de, attr = struct.unpack(e+'hhhhhH', d[off:off+12]); off += 12
            metrics.append((l, r, w, a, de))
    # bitmaps
    f, e = fmt_at(tables[8][1]); off = tables[8][1] + 4
    gc = struct.unpack(e+'I', d[off:off+4])[0]; off += 4
    offs = struct.unpack(e+'%dI' % gc, d[off:off+4*gc]); off += 4*gc
    sizes = struct.unpack(e+'4I', d[off:off+16]); off += 16
    pad = 1 << (f & 3); msbit = bool(f & 8); msbyte = bool(f & 4)
    unit = 1 << ((f >> 4) & 3)
    data = d[off:off+sizes[f & 3]]
    # encodings
    f2, e2 = fmt_at(tables[32][1]); off = tables[32][1] + 4
    min2, max2, minb1, maxb1, default = struct.unpack(e2+'hhhhh', d[off:off+10]); off += 10
    ncode = (max2-min2+1)*(maxb1-minb1+1)
    idx = struct.unpack(e2+'%dH' % ncode, d[off:off+2*ncode])
    # accelerators for font ascent/descent
    acc = tables.get(256, tables.get(2))
    f3, e3 = fmt_at(acc[1]); off = acc[1] + 4 + 8
    fasc, fdesc = struct.unpack(e3+'ii', d[off:off+8])
    def glyph(cp):
        b1, b2 = cp >> 8, cp & 0xff
        if not (minb1 <= b1 <= maxb1 and min2 <= b2 <= max2): return None
        gi = idx[(b1-minb1)*(max2-min2+1) + (b2-min2)]
        if gi == 0xffff: return None
        l, r, w, a, de = metrics[gi]
        rows = a + de; width = r - l
        stride = ((width + pad*8 - 1) // (pad*8)) * pad
        bits = data[offs[gi]:offs[gi]+stride*rows]
        out = []
        for y in range(rows):
            row = bytearray(bits[y*stride:(y+1)*stride])
            if msbyte != msbit and unit > 1:
                # swap within units (not expected here)
                pass
            px = []
            for x in range(width):
                byte = row[x//8]
                bit = (byte >> (7 - x % 8)) & 1 if msbit else (byte >> (x % 8)) & 1
                px.append(bit)
            out.append(px)
        return (l, w, a, de, out)
    return fasc, fdesc, glyph
if __name__ == '__main__':
    fasc, fdesc, glyph = load(sys.argv[1])
    print('ascent', fasc, 'descent', fdesc)
    for ch in sys.argv[2]:
        g = glyph(ord(ch))
        if g is None: print(ch, 'missing'); continue
        l, w, a, de, rows = g
        print(repr(ch), 'lsb', l, 'adv', w, 'asc', a, 'desc', de)
        for r in rows: print(''.join('#' if b else '.' for b in r))


def rust_table(path, extra, overrides=None):
    """The Rust source of render/src/font.rs from the PCF font `path`; `overrides` maps
    a character to the rows (one int each, bit 6 the leftmost column) that replace its
    glyph's."""
    fasc, fdesc, glyph = load(path)
    chars = [chr(c) for c in range(32, 127)] + list(extra)
    rows = fasc + fdesc
    lines = []
    for ch in chars:
        g = glyph(ord(ch))
        assert g is not None, ch
        l, w, a, de, bits = g
        assert l == 0 and w == 7 and a == fasc and de == fdesc, (ch, g[:4])
        values = []
        for r in bits:
            v = 0
            for x, b in enumerate(r):
                v |= b << (6 - x)
            values.append('0x%02x' % v)
        if overrides and ch in overrides:
            assert len(overrides[ch]) == len(values), ch
            values = ['0x%02x' % v for v in overrides[ch]]
        literal = {"'": "\\'", "\\": "\\\\"}.get(ch, ch)
        lines.append("    ('%s', [%s])," % (literal, ", ".join(values)))
    return rows, '\n'.join(lines)
