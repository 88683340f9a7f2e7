#!/usr/bin/env python3
"""Per-zoom weight of a built pyramid: tiles, triangles and gzip bytes (median and largest) of
its .glb and .terrain tiles, and the published geometricError per zoom (median, from the
tileset documents).

    bench/pyramid_stats.py OUT/terrain            # a layer directory written by `build`

A .terrain file may be stored gzip-compressed; its triangles are read from the decompressed
bytes, and "gzip" is the size of the gzip -6 stream either way. A .glb's triangles are its
index accessor's count / 3 (Draco keeps the accessor's count)."""
import gzip
import json
import os
import statistics
import struct
import sys
import zlib


def glb_triangles(data):
    length = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + length])
    total = 0
    for mesh in doc.get("meshes", []):
        for prim in mesh["primitives"]:
            total += doc["accessors"][prim["indices"]]["count"] // 3
    return total


def terrain_triangles(data):
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    vertices = struct.unpack_from("<I", data, 88)[0]
    at = 92 + 6 * vertices
    if vertices > 65536:
        at += (4 - at % 4) % 4
    else:
        at += (2 - at % 2) % 2
    return struct.unpack_from("<I", data, at)[0]


def gzip_size(data):
    if data[:2] == b"\x1f\x8b":
        return len(data)
    c = zlib.compressobj(6, zlib.DEFLATED, 31)
    return len(c.compress(data) + c.flush())


def errors(layer_dir):
    """geometricError of every content tile in the tileset documents, by zoom."""
    out = {}
    stack = ["tileset.json"]
    while stack:
        path = os.path.join(layer_dir, stack.pop())
        if not os.path.exists(path):
            continue
        base = os.path.dirname(os.path.relpath(path, layer_dir))
        doc = json.load(open(path))
        tiles = [doc["root"]]
        while tiles:
            t = tiles.pop()
            uri = t.get("content", {}).get("uri")
            if uri and uri.endswith(".json"):
                stack.append(os.path.normpath(os.path.join(base, uri)))
            elif uri:
                z = int(os.path.normpath(os.path.join(base, uri)).split("/")[0])
                out.setdefault(z, []).append(t["geometricError"])
            tiles.extend(t.get("children", []))
    return out


def main():
    layer_dir = sys.argv[1]
    per = {}
    for root, _, files in os.walk(layer_dir):
        for name in files:
            ext = name.rsplit(".", 1)[-1]
            rel = os.path.relpath(os.path.join(root, name), layer_dir).split("/")
            if ext not in ("glb", "terrain") or len(rel) != 3 or not rel[0].isdigit():
                continue
            data = open(os.path.join(root, name), "rb").read()
            tris = glb_triangles(data) if ext == "glb" else terrain_triangles(data)
            per.setdefault((ext, int(rel[0])), []).append((tris, gzip_size(data)))
    published = errors(layer_dir)
    print("format\tzoom\ttiles\ttri_median\ttri_max\tgzip_kb_median\tgzip_kb_max\tgzip_kb_total\terror_median_m")
    for (ext, z) in sorted(per):
        rows = per[(ext, z)]
        tris = [r[0] for r in rows]
        sizes = [r[1] for r in rows]
        err = published.get(z) if ext == "glb" else None
        print(f"{ext}\t{z}\t{len(rows)}\t{int(statistics.median(tris))}\t{max(tris)}\t"
              f"{statistics.median(sizes) / 1024:.1f}\t{max(sizes) / 1024:.1f}\t"
              f"{sum(sizes) / 1024:.0f}\t{statistics.median(err) if err else '-'}")


if __name__ == "__main__":
    main()
