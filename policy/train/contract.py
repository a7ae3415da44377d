"""The contract of ps1's stage-1 policy (observation layout, actions,
normalisation defaults) from the robot file, shared by training, the test
policies and the importer's examples."""
import os

import yaml  # python3-yaml

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

OBS_FIELDS = ["gravity_body", "gyro_body", "joint_pos", "joint_vel", "prev_action", "com_pos",
              "com_vel", "capture_point", "bos_margin", "feet", "contact"]
# train.py --obs-base-action (a residual policy): the controller's action too
OBS_FIELDS_BASE = OBS_FIELDS + ["base_action"]
LEGS = ["l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll",
        "r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll"]
ACTION_SCALE = 0.25  # rad of target per unit of action
ACTION_CLIP = 4.0


def robot(path=None):
    path = path or os.path.join(ROOT, "robots", "ps1.yaml")
    with open(path) as f:
        return yaml.safe_load(f)


def contract(robot_doc, mean=None, std=None, trained_by="", fields=None):
    import psfile
    fields = fields or OBS_FIELDS
    joints = [j["name"] for j in robot_doc["joints"]]
    n_obs = psfile.obs_size(fields, len(joints), len(LEGS))
    return {
        "version": 1, "robot": robot_doc["name"], "policy_hz": robot_doc["control"]["policy_hz"],
        "joints": joints,
        "kp": [float(j["kp_nm_rad"]) for j in robot_doc["joints"]],
        "kd": [float(j["kd_nm_s_rad"]) for j in robot_doc["joints"]],
        "stance": [float(j["stance_rad"]) for j in robot_doc["joints"]],
        "observation": {"fields": fields,
                        "mean": list(map(float, mean)) if mean is not None else [0.0] * n_obs,
                        "std": list(map(float, std)) if std is not None else [1.0] * n_obs,
                        "clip": 10.0},
        "action": {"joints": LEGS, "scale": [ACTION_SCALE] * len(LEGS), "clip": ACTION_CLIP},
        "trained_by": trained_by,
    }
