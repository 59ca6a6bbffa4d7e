"""Writes the OpenVDB fixtures used by `tests/volume_loading.rs`.

The files are written by the real OpenVDB library (12.x, file format 224,
Blosc compression), through the `openvdb` Python module that ships inside
the `bpy` wheel (Blender as a Python module). To regenerate:

    python3 -m venv /tmp/vdbenv && /tmp/vdbenv/bin/pip install bpy
    SP=$(echo /tmp/vdbenv/lib/python3.*/site-packages/bpy/*/python/lib/python3.*/site-packages)
    PYTHONPATH=$SP /tmp/vdbenv/bin/python tests/data/volumes/make_vdb.py

(a plain `pip install openvdb`-style module works too if one is available).

Fixtures (all small; the expected values below are asserted by the tests):

* `cloud.vdb`: three grids.
  - `density` (float): active voxels over index box [-3, 16] x [0, 11] x [2, 17]
    with value 0.5 + 0.01 i + 0.02 j + 0.03 k, plus an active 8^3 tile of
    value 2.0 over [16, 23] x [0, 7] x [8, 15] (leaf-aligned, so OpenVDB
    stores it as a tile, not as a leaf), and voxel (0, 0, 2) switched off
    with value 9.0 (inactive: must read as 0). Active index bbox:
    [-3, 23] x [0, 11] x [2, 17], i.e. 27 x 12 x 16 voxels.
    Transform: scale (0.1, 0.2, 0.05), translation (1, -2, 0.5)
    (a ScaleTranslateMap).
  - `temperature` (float): a single active voxel (1, 2, 3) = 7.5, uniform
    voxel size 0.5, no translation (a UniformScaleMap).
  - `velocity` (vec3s): one voxel; present to test the "not a float grid"
    error.
* `cloud_half.vdb`: the same `density` grid saved as half floats.
* `rotated.vdb`: a `density` grid with a rotated (affine) transform, to test
  the "transform is not axis-aligned scale+translate" error.
* `mirrored.vdb`: two grids with transform scale (-0.5, 1, 1) (a mirrored
  x axis, still a ScaleTranslateMap):
  - `density`: voxels (0, 0, 0) = 1, (1, 0, 0) = 2, (2, 0, 0) = 3;
  - `negative`: voxel (4, 5, 6) = -1 and (5, 5, 6) = 1, to test the
    "negative voxel" error.
"""

import math
import os

import openvdb as vdb

HERE = os.path.dirname(os.path.abspath(__file__))


def density_value(i, j, k):
    return 0.5 + 0.01 * i + 0.02 * j + 0.03 * k


def make_density(name="density"):
    g = vdb.FloatGrid(0.0)
    g.name = name
    g.gridClass = vdb.GridClass.FOG_VOLUME
    acc = g.getAccessor()
    for k in range(2, 18):
        for j in range(0, 12):
            for i in range(-3, 17):
                acc.setValueOn((i, j, k), density_value(i, j, k))
    # Leaf-aligned 8^3 region: stored as an active tile.
    g.fill((16, 0, 8), (23, 7, 15), 2.0, True)
    # An inactive voxel with a non-zero value.
    acc.setValueOff((0, 0, 2), 9.0)
    g.transform = vdb.createLinearTransform(
        [[0.1, 0, 0, 0], [0, 0.2, 0, 0], [0, 0, 0.05, 0], [1.0, -2.0, 0.5, 1]]
    )
    return g


def main():
    density = make_density()
    temperature = vdb.FloatGrid(0.0)
    temperature.name = "temperature"
    temperature.getAccessor().setValueOn((1, 2, 3), 7.5)
    temperature.transform = vdb.createLinearTransform(0.5)
    velocity = vdb.Vec3SGrid()
    velocity.name = "velocity"
    velocity.getAccessor().setValueOn((0, 0, 0), (1.0, 2.0, 3.0))
    vdb.write(os.path.join(HERE, "cloud.vdb"), [density, temperature, velocity])

    half = make_density()
    half.saveFloatAsHalf = True
    vdb.write(os.path.join(HERE, "cloud_half.vdb"), [half])

    rot = vdb.FloatGrid(0.0)
    rot.name = "density"
    rot.getAccessor().setValueOn((0, 0, 0), 1.0)
    c, s = math.cos(0.5), math.sin(0.5)
    rot.transform = vdb.createLinearTransform(
        [[c, s, 0, 0], [-s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    )
    vdb.write(os.path.join(HERE, "rotated.vdb"), [rot])

    mirror = [[-0.5, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    mir = vdb.FloatGrid(0.0)
    mir.name = "density"
    for i, v in enumerate([1.0, 2.0, 3.0]):
        mir.getAccessor().setValueOn((i, 0, 0), v)
    mir.transform = vdb.createLinearTransform(mirror)
    neg = vdb.FloatGrid(0.0)
    neg.name = "negative"
    neg.getAccessor().setValueOn((4, 5, 6), -1.0)
    neg.getAccessor().setValueOn((5, 5, 6), 1.0)
    neg.transform = vdb.createLinearTransform(mirror)
    vdb.write(os.path.join(HERE, "mirrored.vdb"), [mir, neg])

    for g in (density, temperature):
        print(g.name, g.transform.typeName, g.evalActiveVoxelBoundingBox(),
              "leaves", g.leafCount(), "active", g.activeVoxelCount())
    print("rotated", rot.transform.typeName)
    print("mirrored", mir.transform.typeName, mir.transform.indexToWorld((2, 0, 0)))


if __name__ == "__main__":
    main()
