"""The data paths of training, from the envs to the learner, without copies they do not need.

Two of stable-baselines3's defaults copy data that nothing shares:

* :class:`FreshInfoVecEnv`: SB3's ``DummyVecEnv`` deep-copies every env's ``info`` at every
  step, for envs that reuse one info dict. A MyoExoKnee env builds a new info at every step
  (its entries: the reward terms, ``obs_dict``, ``rwd_dict``, the clinical quantities, the
  episode's ``subject``), so the vector env hands them on as they are: a deep copy of about
  150 objects per env per step was ~10 % of an SBX learner's ``learn`` time;
* :class:`NumpySampleReplayBuffer`: SB3's ``ReplayBuffer`` copies each sampled batch into
  torch tensors, which SBX's learners turn back into numpy arrays before their jitted
  update; this buffer wraps the freshly indexed arrays instead (no copy, same values): the
  copy of the 64 x 256-transition batch of one training call was ~12 % of ``learn``.

:func:`~myoexo.training.train.make_vec_env` builds the first for ``vec_env = "dummy"``,
:func:`~myoexo.training.train.build_model` gives the second to the JAX learners. The
transitions, samples and updates are those of SB3's classes, value for value
(``tests/test_training.py`` checks both against them).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.vec_env import DummyVecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn


class FreshInfoVecEnv(DummyVecEnv):
    """``DummyVecEnv`` for envs that return a new ``info`` dict at every step: the infos are
    handed on without a deep copy. Everything else is ``DummyVecEnv``'s: the truncation flag
    (``info["TimeLimit.truncated"]``), the final observation of an episode
    (``info["terminal_observation"]``) and the automatic reset."""

    def step_wait(self) -> VecEnvStepReturn:
        for i, env in enumerate(self.envs):
            obs, reward, terminated, truncated, info = env.step(self.actions[i])
            self.buf_rews[i] = reward
            done = bool(terminated or truncated)
            self.buf_dones[i] = done
            info["TimeLimit.truncated"] = bool(truncated and not terminated)
            if done:
                info["terminal_observation"] = obs
                obs, self.reset_infos[i] = env.reset()
            self._save_obs(i, obs)
            self.buf_infos[i] = info
        infos = list(self.buf_infos)
        return self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones), infos


class NumpySampleReplayBuffer(ReplayBuffer):
    """``ReplayBuffer`` whose samples wrap the sampled arrays instead of copying them: each
    batch is a new array (indexed out of the buffer), so wrapping is safe; a learner that
    reads them as numpy (SBX) gets them without a copy."""

    def to_torch(self, array: np.ndarray, copy: bool = True) -> Any:
        del copy  # a sampled batch shares memory with nothing
        return torch.as_tensor(array, device=self.device)
