"""Load a URDF with a standard parser (yourdfpy) and print link poses as JSON.

Usage: python3 urdf_check.py MODEL.urdf STATES.json
STATES.json: {"joint name": value, ...}. Output: {"link name": [16 numbers row-major]}
with every link's pose in the base link's frame at that configuration.
Used by tests/kin_urdf.rs to check the exported URDF against the crate's forward
kinematics; exits with status 3 if yourdfpy is not installed (the test then skips).
"""
import json
import sys

try:
    import yourdfpy
except ImportError:
    sys.exit(3)


def main():
    robot = yourdfpy.URDF.load(sys.argv[1], build_scene_graph=True, load_meshes=False)
    with open(sys.argv[2]) as f:
        states = json.load(f)
    robot.update_cfg(states)
    out = {}
    for link in robot.link_map:
        t = robot.get_transform(link, robot.base_link)
        out[link] = [float(x) for x in t.reshape(-1)]
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
