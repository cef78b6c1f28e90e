"""Shared by the scripts that write the project's sphere models (Python's standard library
only): a unit UV sphere (`sphere`, also for scripts/metal-rough-spheres), and two rows of five
of them, two units apart, one material each, as a self-contained glTF (`write`, for
scripts/specular-spheres and scripts/sheen-spheres)."""
import base64
import json
import math
import pathlib
import struct

SEGMENTS, RINGS = 32, 16

ROOT = pathlib.Path(__file__).resolve().parent.parent


def sphere(segments=SEGMENTS, rings=RINGS):
    """Positions (also the normals) of a unit UV sphere of `segments` by `rings`, pole to
    pole, their longitude and latitude fractions, and its triangle indices
    (counter-clockwise seen from outside)."""
    positions, grid, indices = [], [], []
    for r in range(rings + 1):
        theta = math.pi * r / rings  # from +y down to -y
        for s in range(segments + 1):
            phi = 2.0 * math.pi * s / segments
            positions.append(
                (math.sin(theta) * math.sin(phi), math.cos(theta), math.sin(theta) * math.cos(phi))
            )
            grid.append((s / segments, r / rings))
    for r in range(rings):
        for s in range(segments):
            a = r * (segments + 1) + s
            b = a + segments + 1
            if r > 0:
                indices += [a, b, a + 1]
            if r < rings - 1:
                indices += [a + 1, b, b + 1]
    return positions, grid, indices


def write(out, mats, generator, extensions):
    """Writes the ten spheres of `mats` (upper row first) to `out` (a path under the project),
    naming `generator` and the `extensions` the materials use."""
    positions, _, indices = sphere()
    chunks = [
        b"".join(struct.pack("<3f", *p) for p in positions),
        b"".join(struct.pack("<H", i) for i in indices),
    ]
    views, offset = [], 0
    for c in chunks:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(c)})
        offset += (len(c) + 3) // 4 * 4
    data = b"".join(c + b"\0" * ((len(c) + 3) // 4 * 4 - len(c)) for c in chunks)
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": len(positions), "type": "VEC3",
         "min": [-1.0, -1.0, -1.0], "max": [1.0, 1.0, 1.0]},
        {"bufferView": 1, "componentType": 5123, "count": len(indices), "type": "SCALAR"},
    ]
    # One mesh per material, all on the same accessors (the unit sphere is its own normal).
    meshes = [
        {"name": m["name"], "primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 0}, "indices": 1, "material": k}]}
        for k, m in enumerate(mats)
    ]
    nodes = [
        {"mesh": k, "translation": [2.2 * (k % 5) - 4.4, 1.1 if k < 5 else -1.1, 0.0]}
        for k in range(len(mats))
    ]
    uri = f"data:application/octet-stream;base64,{base64.b64encode(data).decode()}"
    doc = {
        "asset": {"version": "2.0", "generator": generator},
        "extensionsUsed": extensions,
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": mats,
        "buffers": [{"byteLength": len(data), "uri": uri}],
        "bufferViews": views,
        "accessors": accessors,
    }
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"{out.relative_to(ROOT)}: {len(mats)} spheres of {len(indices) // 3} triangles, "
          f"{out.stat().st_size} bytes")
