"""Makes the bundled Height example's meshes from Keenan Crane's Spot (public domain):

* `spot_high.obj`: Spot subdivided once (Loop, 23,424 triangles) and displaced along its
  vertex normals by a smooth pattern of bumps (amplitude 0.01, about 0.4 % of the diagonal);
* `spot_low.obj`: Spot decimated to 1,000 triangles by quadric edge collapse keeping its
  texture coordinates, with smooth vertex normals.

Run from the repository root with a Python that has `pymeshlab` and `numpy`
(`python3 -m venv /tmp/venv && /tmp/venv/bin/pip install pymeshlab numpy`):

    /tmp/venv/bin/python tools/make_height_pair.py
"""

import math
import os

import numpy
import pymeshlab

SOURCE = "examples/assets/meshes/spot/spot_triangulated_with_mtl.obj"
FOLDER = "examples/assets/meshes/spot_height"


def bumps(points):
    frequency = 2.0 * math.pi / 0.3
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    return 0.01 * (numpy.sin(frequency * x + 0.3) * numpy.sin(frequency * 1.1 * y) + numpy.sin(frequency * 0.9 * z + 1.0)) / 2.0


def write_obj(path, header, positions, normals, faces, uvs=None, wedge_uvs=None, material=None):
    with open(path, "w") as obj:
        obj.write(f"# {header}\n")
        if material:
            obj.write(f"mtllib {material[0]}\nusemtl {material[1]}\n")
        for p in positions:
            obj.write(f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n")
        for n in normals if normals is not None else []:
            obj.write(f"vn {n[0]:.5f} {n[1]:.5f} {n[2]:.5f}\n")
        if wedge_uvs is not None:
            # one texture coordinate per face corner, shared where equal
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
            for face in faces:
                obj.write("f " + " ".join(f"{v + 1}" for v in face) + "\n")


def main():
    os.makedirs(FOLDER, exist_ok=True)
    high = pymeshlab.MeshSet()
    high.load_new_mesh(SOURCE)
    high.meshing_merge_close_vertices()
    high.meshing_surface_subdivision_loop(iterations=1, threshold=pymeshlab.PercentageValue(0))
    high.compute_normal_per_vertex()
    mesh = high.current_mesh()
    points = mesh.vertex_matrix()
    normals = mesh.vertex_normal_matrix()
    normals = normals / numpy.linalg.norm(normals, axis=1, keepdims=True)
    displaced = points + normals * bumps(points)[:, None]
    faces = mesh.face_matrix()
    # No normals or UVs: the bake reads the high mesh's triangles only.
    write_obj(f"{FOLDER}/spot_high.obj", "Spot (Keenan Crane, public domain) subdivided once and displaced: tools/make_height_pair.py",
              displaced, None, faces)

    low = pymeshlab.MeshSet()
    low.load_new_mesh(SOURCE)
    low.meshing_decimation_quadric_edge_collapse_with_texture(targetfacenum=1000, preserveboundary=True, planarquadric=True)
    low.compute_normal_per_vertex()
    mesh = low.current_mesh()
    normals = mesh.vertex_normal_matrix()
    normals = normals / numpy.linalg.norm(normals, axis=1, keepdims=True)
    write_obj(f"{FOLDER}/spot_low.obj", "Spot (Keenan Crane, public domain) decimated to 1,000 triangles: tools/make_height_pair.py",
              mesh.vertex_matrix(), normals, mesh.face_matrix(), wedge_uvs=mesh.wedge_tex_coord_matrix(), material=("spot_low.mtl", "spot"))
    with open(f"{FOLDER}/spot_low.mtl", "w") as mtl:
        mtl.write("newmtl spot\nKd 1 1 1\nmap_Kd ../spot/spot_texture.png\n")


main()
