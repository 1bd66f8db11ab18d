"""A subprocess vector env that runs a *group* of environments in each worker process.

SB3's ``SubprocVecEnv`` runs one environment per process, so every env step pays one pipe round
trip for about as much physics: on 2 cores it is no faster than one
in-process env (``benchmarks/RESULTS.md``, "Planning"). :class:`GroupedSubprocVecEnv` gives each of
``n_workers`` processes a group of environments and steps the whole group per round trip, so the
pipe cost is shared by the group and both cores do physics.

It is a drop-in SB3 :class:`~stable_baselines3.common.vec_env.VecEnv` with the same semantics as
``DummyVecEnv``: a finished episode is reset inside the worker, ``info["terminal_observation"]``
holds its last observation and ``info["TimeLimit.truncated"]`` says whether it was cut by a time
limit. With the same environment factories, seeds and actions it returns exactly what
``DummyVecEnv`` returns (tested). An error inside a worker is re-raised in the caller with the
worker's message.

Only flat ``Box`` observations are supported (all uam_studio environments use one). Workers that
load torch (the Dynaformer backend) run it on one thread each: the processes are the parallelism.
"""

from __future__ import annotations

import multiprocessing as mp
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.env_util import is_wrapped
from stable_baselines3.common.vec_env.base_vec_env import (
    CloudpickleWrapper,
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from uam_studio.errors import InputError


class WorkerError(RuntimeError):
    """An environment raised inside a :class:`GroupedSubprocVecEnv` worker."""


def _step_group(envs: list[gym.Env], actions: np.ndarray) -> tuple:
    """Step every env of a group once, resetting finished episodes (``DummyVecEnv`` semantics)."""
    obs, rews, dones, infos, reset_infos = [], [], [], [], []
    for env, action in zip(envs, actions, strict=True):
        o, r, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        info["TimeLimit.truncated"] = truncated and not terminated
        reset_info: dict = {}
        if done:
            info["terminal_observation"] = o
            o, reset_info = env.reset()
        obs.append(o)
        rews.append(r)
        dones.append(done)
        infos.append(info)
        reset_infos.append(reset_info)
    return np.stack(obs), np.asarray(rews, dtype=np.float32), np.asarray(dones, dtype=bool), infos, reset_infos


def _worker(remote, parent_remote, env_fns: CloudpickleWrapper) -> None:
    """Worker loop: build the group's envs, answer commands until ``close``."""
    parent_remote.close()
    try:
        envs = [fn() for fn in env_fns.var]
        build_error = None
    except Exception as exc:  # noqa: BLE001 - reported to the caller at its first command
        envs, build_error = [], f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"
    if "torch" in sys.modules:  # a Dynaformer backend: the workers are the parallelism, one thread each
        sys.modules["torch"].set_num_threads(1)
    while True:
        try:
            cmd, data = remote.recv()
        except EOFError:
            break
        try:
            if build_error is not None and cmd != "close":
                remote.send(("error", build_error))
                continue
            if cmd == "step":
                out: Any = _step_group(envs, data)
            elif cmd == "reset":
                seeds, options = data
                pairs = [env.reset(seed=s, **({"options": o} if o else {})) for env, s, o in zip(envs, seeds, options)]
                out = (np.stack([p[0] for p in pairs]), [p[1] for p in pairs])
            elif cmd == "spaces":
                out = (envs[0].observation_space, envs[0].action_space)
            elif cmd == "get_attr":
                name, local = data
                out = [envs[i].get_wrapper_attr(name) for i in local]
            elif cmd == "set_attr":
                name, value, local = data
                out = [envs[i].set_wrapper_attr(name, value) for i in local]  # one None per env
            elif cmd == "env_method":
                name, args, kwargs, local = data
                out = [envs[i].get_wrapper_attr(name)(*args, **kwargs) for i in local]
            elif cmd == "is_wrapped":
                wrapper, local = data
                out = [is_wrapped(envs[i], wrapper) for i in local]
            elif cmd == "render":
                out = [env.render() for env in envs]
            elif cmd == "close":
                for env in envs:
                    env.close()
                remote.send(("ok", None))
                remote.close()
                break
            else:
                raise NotImplementedError(f"unknown command {cmd!r}")
            remote.send(("ok", out))
        except Exception as exc:  # noqa: BLE001 - every worker error goes back to the caller
            remote.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))


class GroupedSubprocVecEnv(VecEnv):
    """``len(env_fns)`` environments in ``n_workers`` processes, stepped a group per pipe round trip.

    :param env_fns: environment factories (as for ``DummyVecEnv``; ``make_vec_env`` passes them)
    :param n_workers: worker processes, 1 to ``len(env_fns)``; environments are split into
        contiguous groups of near-equal size (2 workers x 8 envs: envs 0-7 and 8-15)
    :param start_method: multiprocessing start method; default ``forkserver`` where available
        (as SB3's ``SubprocVecEnv``), else ``spawn``
    """

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], n_workers: int = 2,
                 start_method: str | None = None) -> None:
        n_envs = len(env_fns)
        if n_envs < 1:
            raise InputError("env_fns", "is empty; allowed >= 1 environment factory")
        if not 1 <= int(n_workers) <= n_envs:
            raise InputError("n_workers", f"{n_workers!r} is out of range; allowed 1 to {n_envs} (the number of envs)")
        self.groups = [list(g) for g in np.array_split(np.arange(n_envs), int(n_workers))]
        self._where = {int(g): (w, k) for w, group in enumerate(self.groups) for k, g in enumerate(group)}
        if start_method is None:
            start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        ctx: Any = mp.get_context(start_method)  # its stubs lack Process
        self.remotes, self.processes = [], []
        for group in self.groups:
            remote, work_remote = ctx.Pipe()
            fns = CloudpickleWrapper([env_fns[int(i)] for i in group])
            proc = ctx.Process(target=_worker, args=(work_remote, remote, fns), daemon=True)
            proc.start()
            work_remote.close()
            self.remotes.append(remote)
            self.processes.append(proc)
        self.closed = False
        self.waiting = False
        for remote in self.remotes:
            remote.send(("spaces", None))
        try:
            observation_space, action_space = self._answers(self.remotes)[0]
        except WorkerError:
            self.close()
            raise
        if not isinstance(observation_space, gym.spaces.Box):
            self.close()
            raise InputError("observation_space", f"{observation_space} is not supported; allowed: a flat Box")
        super().__init__(n_envs, observation_space, action_space)

    # -- plumbing ----------------------------------------------------------------------------
    @staticmethod
    def _recv(remote) -> tuple[str, Any]:
        try:
            return remote.recv()
        except (EOFError, ConnectionResetError):
            return "error", "a worker process exited (could it build its environments?)"

    def _answers(self, remotes) -> list[Any]:
        # read every reply before raising, so no pipe is left holding a stale answer
        replies = [self._recv(r) for r in remotes]
        for status, out in replies:
            if status == "error":
                raise WorkerError(out)
        return [out for _, out in replies]

    def _call(self, cmd: str, make_data: Callable[[list[int]], Any], indices: VecEnvIndices) -> list[Any]:
        """Send ``cmd`` to the workers holding ``indices``; the answers in the order of ``indices``."""
        wanted = [self._where[int(i)] for i in self._get_indices(indices)]
        local: dict[int, list[int]] = {}
        for w, k in wanted:
            local.setdefault(w, []).append(k)
        for w, ks in local.items():
            self.remotes[w].send((cmd, make_data(ks)))
        answers = dict(zip(local, self._answers([self.remotes[w] for w in local]), strict=True))
        by_env = {(w, k): a for w, ks in local.items() for k, a in zip(ks, answers[w], strict=True)}
        return [by_env[wk] for wk in wanted]

    # -- VecEnv API --------------------------------------------------------------------------
    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions)
        for remote, group in zip(self.remotes, self.groups):
            remote.send(("step", actions[group]))
        self.waiting = True

    def step_wait(self) -> VecEnvStepReturn:
        parts = self._answers(self.remotes)
        self.waiting = False
        obs = np.concatenate([p[0] for p in parts])
        rews = np.concatenate([p[1] for p in parts])
        dones = np.concatenate([p[2] for p in parts])
        infos = [info for p in parts for info in p[3]]
        self.reset_infos = [info for p in parts for info in p[4]]
        return obs, rews, dones, infos

    def reset(self) -> VecEnvObs:
        for remote, group in zip(self.remotes, self.groups):
            remote.send(("reset", ([self._seeds[i] for i in group], [self._options[i] for i in group])))
        parts = self._answers(self.remotes)
        self.reset_infos = [info for p in parts for info in p[1]]
        self._reset_seeds()
        self._reset_options()
        return np.concatenate([p[0] for p in parts])

    def close(self) -> None:
        if self.closed:
            return
        if self.waiting:
            for remote in self.remotes:
                self._recv(remote)
        for remote in self.remotes:
            try:
                remote.send(("close", None))
            except BrokenPipeError:
                continue
            self._recv(remote)
        for proc in self.processes:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.terminate()
        self.closed = True

    def get_images(self) -> Sequence[np.ndarray | None]:
        for remote in self.remotes:
            remote.send(("render", None))
        return [img for part in self._answers(self.remotes) for img in part]

    def has_attr(self, attr_name: str) -> bool:
        try:
            self.get_attr(attr_name)
        except WorkerError as exc:
            if str(exc).startswith("AttributeError"):
                return False
            raise
        return True

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return self._call("get_attr", lambda local: (attr_name, local), indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._call("set_attr", lambda local: (attr_name, value, local), indices)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        return self._call("env_method", lambda local: (method_name, method_args, method_kwargs, local), indices)

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return self._call("is_wrapped", lambda local: (wrapper_class, local), indices)


__all__ = ["GroupedSubprocVecEnv", "WorkerError"]
