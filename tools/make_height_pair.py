"""Makes a high/low mesh pair for the Height kind from a licensed mesh: the high mesh subdivided
once (Loop) and displaced along its vertex normals by a smooth pattern of bumps, the low mesh
decimated by quadric edge collapse keeping its texture coordinates, with smooth normals.

The bundled example (`examples/assets/meshes/spot_height`, from Keenan Crane's Spot, public
domain: high 23,424 triangles with bumps of amplitude 0.01, low 1,000 triangles):

    python tools/make_height_pair.py

The benchmark's corpus pair (the flight helmet's hose, CC0: `target/height_pairs/hose`):

    python tools/make_height_pair.py --source ../shared/assets/meshes/flight_helmet/FlightHelmet.obj \\
        --object Hose_low --faces 2000 --amplitude 0.002 --period 0.03 --out target/height_pairs/hose

Needs a Python with `pymeshlab` and `numpy`
(`python3 -m venv /tmp/venv && /tmp/venv/bin/pip install pymeshlab numpy`).
"""

import argparse
import math
import os
import tempfile

import numpy
import pymeshlab


def bumps(points, amplitude, period):
    frequency = 2.0 * math.pi / period
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    return amplitude * (numpy.sin(frequency * x + 0.3) * numpy.sin(frequency * 1.1 * y) + numpy.sin(frequency * 0.9 * z + 1.0)) / 2.0


def one_object(source, name):
    """The OBJ text of one object (`o name`) of `source`, its indices renumbered."""
    positions, uvs, normals, faces = [], [], [], []
    current = None
    for line in open(source):
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            positions.append(line)
        elif parts[0] == "vt":
            uvs.append(line)
        elif parts[0] == "vn":
            normals.append(line)
        elif parts[0] == "o":
            current = parts[1]
        elif parts[0] == "f" and current == name:
            faces.append(parts[1:])
    used = [{}, {}, {}]
    out_faces = []
    for face in faces:
        corners = []
        for corner in face:
            fields = corner.split("/")
            renumbered = []
            for slot, field in enumerate(fields):
                if field == "":
                    renumbered.append("")
                    continue
                index = int(field)
                table = used[slot]
                if index not in table:
                    table[index] = len(table) + 1
                renumbered.append(str(table[index]))
            corners.append("/".join(renumbered))
        out_faces.append("f " + " ".join(corners) + "\n")
    lines = []
    for slot, source_lines in enumerate([positions, uvs, normals]):
        for index, _ in sorted(used[slot].items(), key=lambda item: item[1]):
            lines.append(source_lines[index - 1])
    return "".join(lines) + "".join(out_faces)


def write_obj(path, header, positions, normals, faces, wedge_uvs=None, material=None):
    with open(path, "w") as obj:
        obj.write(f"# {header}\n")
        if material:
            obj.write(f"mtllib {material[0]}\nusemtl {material[1]}\n")
        for p in positions:
            obj.write(f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n")
        for n in normals if normals is not None else []:
            obj.write(f"vn {n[0]:.5f} {n[1]:.5f} {n[2]:.5f}\n")
        if wedge_uvs is not None:
            # one texture coordinate per distinct face-corner value
            index = {}
            corner_uv = []
            lines = []
            for uv in wedge_uvs.reshape(-1, 2):
                key = (round(float(uv[0]), 6), round(float(uv[1]), 6))
                if key not in index:
                    index[key] = len(index) + 1
                    lines.append(f"vt {key[0]:.6f} {key[1]:.6f}\n")
                corner_uv.append(index[key])
            obj.writelines(lines)
            for f, face in enumerate(faces):
                corners = [f"{face[c] + 1}/{corner_uv[3 * f + c]}/{face[c] + 1}" for c in range(3)]
                obj.write("f " + " ".join(corners) + "\n")
        else:
            # No normals or UVs: the bake reads the high mesh's triangles only.
            for face in faces:
                obj.write("f " + " ".join(f"{v + 1}" for v in face) + "\n")


def main():
    arguments = argparse.ArgumentParser()
    arguments.add_argument("--source", default="examples/assets/meshes/spot/spot_triangulated_with_mtl.obj")
    arguments.add_argument("--object", default=None, help="take only this `o` object of the source")
    arguments.add_argument("--faces", type=int, default=1000, help="triangles of the low mesh")
    arguments.add_argument("--amplitude", type=float, default=0.01)
    arguments.add_argument("--period", type=float, default=0.3)
    arguments.add_argument("--out", default="examples/assets/meshes/spot_height")
    arguments.add_argument("--name", default="spot")
    arguments.add_argument("--texture", default="../spot/spot_texture.png")
    options = arguments.parse_args()
    os.makedirs(options.out, exist_ok=True)
    source = options.source
    if options.object:
        source = os.path.join(tempfile.mkdtemp(), "object.obj")
        with open(source, "w") as obj:
            obj.write(one_object(options.source, options.object))
    credit = f"{os.path.basename(options.source)}{' ' + options.object if options.object else ''}"

    high = pymeshlab.MeshSet()
    high.load_new_mesh(source)
    high.meshing_merge_close_vertices()
    high.meshing_surface_subdivision_loop(iterations=1, threshold=pymeshlab.PercentageValue(0))
    high.compute_normal_per_vertex()
    mesh = high.current_mesh()
    points = mesh.vertex_matrix()
    normals = mesh.vertex_normal_matrix()
    normals = normals / numpy.linalg.norm(normals, axis=1, keepdims=True)
    displaced = points + normals * bumps(points, options.amplitude, options.period)[:, None]
    faces = mesh.face_matrix()
    write_obj(f"{options.out}/{options.name}_high.obj",
              f"{credit} subdivided once and displaced by bumps of {options.amplitude}: tools/make_height_pair.py",
              displaced, None, faces)

    low = pymeshlab.MeshSet()
    low.load_new_mesh(source)
    low.meshing_decimation_quadric_edge_collapse_with_texture(targetfacenum=options.faces, preserveboundary=True, planarquadric=True)
    low.compute_normal_per_vertex()
    mesh = low.current_mesh()
    normals = mesh.vertex_normal_matrix()
    normals = normals / numpy.linalg.norm(normals, axis=1, keepdims=True)
    write_obj(f"{options.out}/{options.name}_low.obj", f"{credit} decimated to {options.faces} triangles: tools/make_height_pair.py",
              mesh.vertex_matrix(), normals, mesh.face_matrix(), wedge_uvs=mesh.wedge_tex_coord_matrix(),
              material=(f"{options.name}_low.mtl", options.name))
    with open(f"{options.out}/{options.name}_low.mtl", "w") as mtl:
        mtl.write(f"newmtl {options.name}\nKd 1 1 1\nmap_Kd {options.texture}\n")


main()
