"""Reads back a Paraview series written by flexmb_results::vtk with readers that owe it
nothing: xml.etree for the .pvd collection and each file's XML header, meshio for the data of
every .vtu the collection lists. Prints what they found as JSON for tests/results/vtk.rs to check.

Usage: python3 read_vtk.py DIR/results.pvd
Exit status 3 when meshio is not installed (pip install meshio).
"""

import json
import os
import sys
import xml.etree.ElementTree as ET

try:
    import meshio
    import numpy
except ImportError as e:
    print(f"cannot import {e.name}: pip install meshio", file=sys.stderr)
    sys.exit(3)


def rows(array, count):
    """An array as a list of rows (one per point or cell), whatever its components."""
    return numpy.asarray(array).reshape(count, -1).tolist()


def dataset(entry, directory):
    path = os.path.join(directory, entry.get("file"))
    header = ET.parse(path).getroot()
    mesh = meshio.read(path, file_format="vtu")
    npoints = len(mesh.points)
    ncells = sum(len(block.data) for block in mesh.cells)
    return {
        "timestep": entry.get("timestep"),
        "part": entry.get("part"),
        "name": entry.get("name"),
        "file": entry.get("file"),
        "header": dict(header.attrib),
        "types": {a.get("Name"): a.get("type") for a in header.iter("DataArray")},
        "points": mesh.points.tolist(),
        "cells": [[block.type, block.data.tolist()] for block in mesh.cells],
        "point_data": {k: rows(v, npoints) for k, v in mesh.point_data.items()},
        "cell_data": {
            k: rows(numpy.concatenate([numpy.asarray(b).reshape(len(b), -1) for b in v]), ncells)
            for k, v in mesh.cell_data.items()
        },
    }


def main():
    pvd = sys.argv[1]
    root = ET.parse(pvd).getroot()
    collection = root.find("Collection")
    out = {
        "header": dict(root.attrib),
        "datasets": [
            dataset(d, os.path.dirname(pvd)) for d in collection.findall("DataSet")
        ],
    }
    json.dump(out, sys.stdout)


main()
