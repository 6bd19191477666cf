"""Load a URDF with a standard parser (yourdfpy, with trimesh for its meshes) and print
what it read as JSON.

Usage: python3 urdf_check.py MODEL.urdf STATES.json
STATES.json: {"joint name": value, ...}. Output:
  {"poses": {"link name": [16 numbers row-major]},   every link's pose in the base
                                                       link's frame at that configuration
   "meshes": {"link name": {...}}}                     links whose visual is a mesh file:
     "volume", "watertight", "vertices" of the mesh as trimesh loaded it;
     "center_mass" and "inertia" (unit mass, about the centre of mass) that trimesh
     computes from the mesh; "inertial_origin", "mass" and "inertia_urdf" as the
     URDF's <inertial> says.
Used by tests/kin_urdf.rs to check the exported URDF against the crate's forward
kinematics and its meshes and inertia against trimesh; exits with status 3 if yourdfpy
is not installed (the test then skips).
"""
import json
import sys

try:
    import yourdfpy
except ImportError:
    sys.exit(3)


def main():
    robot = yourdfpy.URDF.load(sys.argv[1], build_scene_graph=True, load_meshes=True)
    with open(sys.argv[2]) as f:
        states = json.load(f)
    robot.update_cfg(states)
    poses = {}
    for link in robot.link_map:
        t = robot.get_transform(link, robot.base_link)
        poses[link] = [float(x) for x in t.reshape(-1)]
    meshes = {}
    for name, link in robot.link_map.items():
        mesh_geoms = [v.geometry.mesh for v in link.visuals if v.geometry.mesh is not None]
        if not mesh_geoms:
            continue
        # The mesh yourdfpy loaded for this link (the scene names it by its file name).
        key = mesh_geoms[0].filename.split("/")[-1]
        mesh = robot.scene.geometry[key]
        inertial = link.inertial
        meshes[name] = {
            "volume": float(mesh.volume),
            "watertight": bool(mesh.is_watertight),
            "vertices": int(len(mesh.vertices)),
            "center_mass": [float(x) for x in mesh.center_mass],
            "inertia": [float(x) for x in (mesh.moment_inertia / mesh.mass).reshape(-1)],
            "inertial_origin": [float(x) for x in inertial.origin[:3, 3]],
            "mass": float(inertial.mass),
            "inertia_urdf": [float(x) for x in inertial.inertia.reshape(-1)],
        }
    json.dump({"poses": poses, "meshes": meshes}, sys.stdout)


if __name__ == "__main__":
    main()
