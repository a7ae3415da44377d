"""ctypes binding of build/libpsenv.so (tools/psenv/ps_env.h): the batched
C training environment."""
import ctypes
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# The capture-point controller's tunables (train.py, eval.py --expert): quick,
# the runtime's; slow, as before its 2026-12-03 change (tools/psenv/ps_env.h)
EXPERTS = ("quick", "slow")
INFO_KEYS = ("fell", "ended", "t_s", "push_dv", "r_balance", "r_quality", "com_z", "pushes",
             "expert_swing", "quiet_s", "feet_apart_m", "feet_stagger_m", "feet_lateral_m")
# the critic's privileged state (PS_ENV_INFO_PRIV .. of the info; train.py --priv-critic)
PRIV_KEYS = ("com_x", "com_y", "com_dz", "vel_x", "vel_y", "vel_z", "force_l", "force_r",
             "push_x", "push_y", "push_left_s", "push_next_s", "held", "friction", "strength",
             "latency_ms", "torso_mass", "pelvis_mass", "torso_com_x", "torso_com_y",
             "torso_com_z")
PRIV = slice(len(INFO_KEYS), len(INFO_KEYS) + len(PRIV_KEYS))
INFO = len(INFO_KEYS) + len(PRIV_KEYS)  # floats of info per environment and step (PS_ENV_INFO)


class EnvCfg(ctypes.Structure):
    _fields_ = [("n_envs", ctypes.c_uint32), ("n_threads", ctypes.c_uint32),
                ("seed", ctypes.c_uint64), ("episode_s", ctypes.c_float),
                ("push_dv_max_m_s", ctypes.c_float), ("is_dr", ctypes.c_int),
                ("is_expert", ctypes.c_int), ("push_dv_min_m_s", ctypes.c_double),
                ("harness_p", ctypes.c_float), ("focus_p", ctypes.c_float),
                ("focus_dir_rad", ctypes.c_float), ("is_expert_slow", ctypes.c_int),
                ("is_ramp_start", ctypes.c_int), ("is_obs_base_action", ctypes.c_int)]


def _f32(a):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_float))


class Env:
    def __init__(self, n_envs, n_threads=2, seed=1, episode_s=6.0, push_dv_max=0.8, dr=True,
                 robot=None, lib=None, push_dv_min=0.05, harness_p=0.0, focus_p=0.0,
                 focus_dir_rad=0.0, expert="quick", ramp_start=False, obs_base_action=False):
        if expert not in EXPERTS:
            raise ValueError("expert %r: one of %s" % (expert, ", ".join(EXPERTS)))
        self.lib = ctypes.CDLL(lib or os.path.join(ROOT, "build", "libpsenv.so"))
        L = self.lib
        L.ps_env_create.argtypes = [ctypes.c_char_p, ctypes.POINTER(EnvCfg),
                                    ctypes.POINTER(ctypes.c_void_p), ctypes.c_char_p,
                                    ctypes.c_size_t]
        L.ps_env_obs_size.argtypes = L.ps_env_act_size.argtypes = [ctypes.c_void_p]
        L.ps_env_obs_size.restype = L.ps_env_act_size.restype = ctypes.c_uint32
        L.ps_env_info_size.argtypes = []
        L.ps_env_info_size.restype = ctypes.c_uint32
        if L.ps_env_info_size() != INFO:  # the info buffer below is sized by INFO
            raise RuntimeError("libpsenv gives %d floats of info a step, psenv.INFO_KEYS and "
                               "PRIV_KEYS name %d: rebuild it (make build/libpsenv.so)"
                               % (L.ps_env_info_size(), INFO))
        L.ps_env_reset.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_float)]
        L.ps_env_step.argtypes = [ctypes.c_void_p] + [ctypes.POINTER(ctypes.c_float)] * 3 + [
            ctypes.POINTER(ctypes.c_uint8)] + [ctypes.POINTER(ctypes.c_float)] * 2
        L.ps_env_destroy.argtypes = [ctypes.c_void_p]
        L.ps_env_set_push_dv_max.argtypes = [ctypes.c_void_p, ctypes.c_float]
        L.ps_env_set_push.argtypes = [ctypes.c_void_p, ctypes.c_uint32] + [ctypes.c_float] * 4
        cfg = EnvCfg(n_envs, n_threads, seed, episode_s, push_dv_max, int(dr), 1, push_dv_min,
                     harness_p, focus_p, focus_dir_rad, int(expert == "slow"), int(ramp_start),
                     int(obs_base_action))
        err = ctypes.create_string_buffer(1024)
        h = ctypes.c_void_p()
        path = (robot or os.path.join(ROOT, "robots", "ps1.yaml")).encode()
        rc = L.ps_env_create(path, ctypes.byref(cfg), ctypes.byref(h), err, 1024)
        if rc != 0:
            raise RuntimeError("ps_env_create: %d %s" % (rc, err.value.decode()))
        self.h = h
        self.n = n_envs
        self.n_obs = L.ps_env_obs_size(h)
        self.n_act = L.ps_env_act_size(h)
        self.obs = np.zeros((n_envs, self.n_obs), np.float32)
        self.rew = np.zeros(n_envs, np.float32)
        self.done = np.zeros(n_envs, np.uint8)
        self.expert = np.zeros((n_envs, self.n_act), np.float32)
        self.info = np.zeros((n_envs, INFO), np.float32)

    def reset(self):
        rc = self.lib.ps_env_reset(self.h, _f32(self.obs))
        if rc != 0:
            raise RuntimeError("ps_env_reset: %d" % rc)
        return self.obs.copy()

    def step(self, act):
        a = np.ascontiguousarray(act, np.float32)
        rc = self.lib.ps_env_step(self.h, _f32(a), _f32(self.obs), _f32(self.rew),
                                  self.done.ctypes.data_as(ctypes.POINTER(ctypes.c_uint8)),
                                  _f32(self.expert), _f32(self.info))
        if rc != 0:
            raise RuntimeError("ps_env_step: %d" % rc)
        return self.obs.copy(), self.rew.copy(), self.done.astype(bool), self.expert.copy(), \
            self.info.copy()

    def set_push_dv_max(self, dv):
        self.lib.ps_env_set_push_dv_max(self.h, float(dv))

    def set_push(self, i, t_s, dur_s, dv, dir_rad):
        """Environment i's next episodes: this one push (dur_s <= 0: random again)."""
        if self.lib.ps_env_set_push(self.h, i, t_s, dur_s, dv, dir_rad) != 0:
            raise ValueError("ps_env_set_push(%d, %g, %g, %g, %g)" % (i, t_s, dur_s, dv, dir_rad))

    def close(self):
        if self.h:
            self.lib.ps_env_destroy(self.h)
            self.h = None
