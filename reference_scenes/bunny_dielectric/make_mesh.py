"""Make ``bunny.ply`` (this folder) from the Stanford bunny's ``bun_zipper.ply``.

    python reference_scenes/bunny_dielectric/make_mesh.py path/to/bun_zipper.ply

The original (35,947 vertices, 69,451 faces, 5 holes, 1,113 unreferenced vertices) is
closed, decimated to about 4,000 faces and written as a binary PLY of vertex positions and
triangles only, in the original's coordinates (the scene's ``scale`` and ``translate`` place
it). It refuses to write a mesh that is not watertight and two-manifold.
"""

import sys
from pathlib import Path

import pymeshlab

TARGET_FACES = 4000
OUT = Path(__file__).with_name("bunny.ply")


def topology(ms):
    topo = ms.get_topological_measures()
    return {key: topo[key] for key in ("boundary_edges", "number_holes", "is_mesh_two_manifold",
                                      "non_two_manifold_edges", "non_two_manifold_vertices",
                                      "connected_components_number")}


def make(source, out=OUT):
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(source))
    # Close the scan (the recipe of reference_scenes/README.md "Meshes with holes"): the first
    # pass leaves one 3-edge hole; selfintersection=False lets the second close it.
    ms.meshing_remove_unreferenced_vertices()
    for _ in range(2):
        ms.meshing_close_holes(maxholesize=1000, selfintersection=False)
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=TARGET_FACES, preservetopology=True,
                                                preservenormal=True, planarquadric=True, qualitythr=0.5)
    ms.meshing_remove_unreferenced_vertices()
    topo = topology(ms)
    mesh = ms.current_mesh()
    if topo["boundary_edges"] or not topo["is_mesh_two_manifold"] or topo["connected_components_number"] != 1:
        raise SystemExit(f"not a closed two-manifold mesh: {topo}")
    ms.save_current_mesh(str(out), binary=True, save_vertex_color=False, save_vertex_quality=False,
                         save_vertex_normal=False, save_vertex_radius=False, save_face_color=False,
                         save_face_quality=False, save_wedge_texcoord=False, save_wedge_normal=False)
    return mesh.vertex_number(), mesh.face_number(), topo


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    vertices, faces, topo = make(sys.argv[1])
    print(f"{OUT}: {vertices} vertices, {faces} faces, {OUT.stat().st_size} bytes; {topo}")
