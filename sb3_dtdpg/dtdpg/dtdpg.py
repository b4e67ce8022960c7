import dataclasses
import warnings
from collections.abc import Iterable, Iterator, Mapping
from typing import Any, ClassVar, TypeVar

import torch as th
from gymnasium import spaces
from stable_baselines3 import DDPG
from stable_baselines3.common.buffers import NStepReplayBuffer, ReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, ConvertCallback, EvalCallback
from stable_baselines3.common.noise import ActionNoise, VectorizedActionNoise
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule

from sb3_dtdpg import env_settings
from sb3_dtdpg.common.buffers import FastNStepReplayBuffer, reward_components_buffer
from sb3_dtdpg.common.callbacks import CurriculumTransferCallback
from sb3_dtdpg.common.checks import (
    check_action_noise,
    check_callback,
    check_folder,
    check_log_interval,
    check_off_policy_settings,
    check_switches,
    check_total_timesteps,
)
from sb3_dtdpg.common.noise import decaying_noise
from sb3_dtdpg.common.phases import Phase, check_env_phases, default_curriculum, parse_phases
from sb3_dtdpg.dtdpg.lean import LeanStep
from sb3_dtdpg.dtdpg.policies import CnnPolicy, DTDPGPolicy, MlpPolicy, MultiInputPolicy

SelfDTDPG = TypeVar("SelfDTDPG", bound="DTDPG")


class DTDPG(LeanStep, DDPG):
    """
    Deep Transfer Deterministic Policy Gradient (DT-DPG).

    Paper: R. Zhong, X. Liu, Y. Liu, Y. Chen, X. Wang,
    "Path Design and Resource Management for NOMA enhanced Indoor Intelligent Robots"
    (Section IV, Algorithm 1; hyperparameters in Section V, Table I).

    DDPG with three changes: batch-normalised actor and critic (:class:`~sb3_dtdpg.dtdpg.policies.DTDPGPolicy`),
    an Ornstein-Uhlenbeck exploration noise whose scale falls linearly per episode
    (:class:`~sb3_dtdpg.common.noise.LinearDecayOUNoise`), and a curriculum of reward phases trained one after
    the other, the networks carrying over from one phase to the next
    (:class:`~sb3_dtdpg.common.callbacks.CurriculumTransferCallback`, added by :meth:`learn`). The curriculum
    state is kept in ``model.curriculum_state`` and saved with the model, so repeated ``learn()`` calls, and
    ``load()`` then ``learn(..., reset_num_timesteps=False)``, continue in the same phase. An ``EvalCallback`` given
    to :meth:`learn` evaluates on the current phase's reward (its eval env follows the curriculum) and its
    ``best_model.zip`` is the best on the last phase's reward; Optuna trial callbacks keep their env's reward.

    The constructor's defaults are SB3's DDPG defaults (generic settings; the batch-norm policy's own hidden
    layers), with one phase of decaying OU noise unless the env offers its own curriculum. The settings for the
    mission env (``noma_radiomap``) are named presets: ``DTDPG("MlpPolicy", env, **preset("tuned"))`` with
    :func:`sb3_dtdpg.presets.preset`, the best measured settings (docs/BENCHMARKS.md), or ``preset("paper")``,
    the paper's Table I (docs/ZOO.md, "Presets").

    :param policy: The policy model to use (``"MlpPolicy"``, ``"CnnPolicy"`` for images, ``"MultiInputPolicy"`` for
        ``Dict`` observations: the batch-norm policy with a flatten, CNN or combined features extractor)
    :param env: The environment to learn from (if registered in Gym, can be str)
    :param learning_rate: learning rate for adam optimizer,
        the same learning rate will be used for all networks (Q-Values, Actor and Value function)
        it can be a function of the current progress remaining (from 1 to 0)
    :param buffer_size: size of the replay buffer
    :param learning_starts: how many steps of the model to collect transitions for before learning starts
    :param batch_size: Minibatch size for each gradient update
    :param tau: the soft update coefficient ("Polyak update", between 0 and 1)
    :param gamma: the discount factor
    :param train_freq: Update the model every ``train_freq`` steps. Alternatively pass a tuple of frequency and unit
        like ``(5, "step")`` or ``(2, "episode")``.
    :param gradient_steps: How many gradient steps to do after each rollout (see ``train_freq``)
        Set to ``-1`` means to do as many gradient steps as steps done in the environment
        during the rollout.
    :param action_noise: the action noise; None (default): a :class:`~sb3_dtdpg.common.noise.LinearDecayOUNoise`
        armed from the first phase (no noise when that phase has no ``sigma``), re-armed by each phase. A given
        noise is used as is with the default phases; phases given with a ``sigma`` re-arm it (see
        :func:`~sb3_dtdpg.common.noise.rearm_noise`).
    :param replay_buffer_class: Replay buffer class to use (for instance ``HerReplayBuffer``).
        If ``None``: :class:`~sb3_dtdpg.common.buffers.RewardComponentsReplayBuffer` when a phase relabels
        the replay buffer (:class:`~sb3_dtdpg.common.buffers.RewardComponentsNStepReplayBuffer` with
        ``n_steps > 1``), else with ``n_steps > 1`` on a ``Box`` observation space
        :class:`~sb3_dtdpg.common.buffers.FastNStepReplayBuffer` (SB3's ``NStepReplayBuffer``, sampled faster with
        the same numbers), else SB3's choice.
    :param replay_buffer_kwargs: Keyword arguments to pass to the replay buffer on creation.
    :param optimize_memory_usage: Enable a memory efficient variant of the replay buffer
        at a cost of more complexity.
        See https://github.com/DLR-RM/stable-baselines3/issues/37#issuecomment-637501195
    :param n_steps: When n_step > 1, uses n-step return (with the NStepReplayBuffer) when updating the Q-value network.
    :param tensorboard_log: the log location for tensorboard (if None, no logging)
    :param policy_kwargs: additional arguments to be passed to the policy on creation
        (``net_arch``, ``activation_fn``, ``batch_norm_momentum``, ``batch_norm_eps``, ...)
    :param verbose: Verbosity level: 0 for no output, 1 for info messages (such as device or wrappers used), 2 for
        debug messages
    :param seed: Seed for the pseudo random generators
    :param device: Device (cpu, cuda, ...) on which the code should be run.
        Setting it to auto, the code will be run on the GPU if possible.
    :param phases: The curriculum: :class:`~sb3_dtdpg.common.phases.Phase` objects or dicts of their fields
        (YAML). None: :func:`~sb3_dtdpg.common.phases.default_curriculum`, the env's own ``default_curriculum``
        when it offers one, else a single phase that leaves the reward alone.
    :param curriculum_save_path: Folder where the model is saved at the end of each phase
        (``phase_<k>_<name>.zip``, the paper's theta_X); None: not saved. An existing file there is refused, and so
        is a first ``learn()`` where the folder holds these phase files already (an earlier run's: one folder per run).
        Not saved with the model (a copy of a run would write into the original's folder): give it to
        :meth:`load` again to keep saving the phases.
    :param reinitialize_at_transfer: Re-initialise the networks at each transfer instead of carrying
        them over (ablation of the transfer, :meth:`reinitialize`)
    :param lean: Train and act with the lean step (:mod:`sb3_dtdpg.dtdpg.lean`): SB3's TD3/DDPG update and
        acting path with the same numbers bit for bit for the same seed, in fewer operations (docs/BENCHMARKS.md,
        "Training speed"); False: SB3's generic ``train()`` and ``_sample_action()`` (the reference the lean step is
        tested against)
    :param backprop: In the lean step, run the MLP networks with their backward passes written out
        (:mod:`sb3_dtdpg.dtdpg.backprop`, the same numbers as autograd); False, or networks it does not cover
        (images, ``Dict`` observations, layer norm, other activations): autograd
    :param _init_setup_model: Whether or not to build the network at the creation of the instance
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "CnnPolicy": CnnPolicy,
        "MultiInputPolicy": MultiInputPolicy,
    }
    policy: DTDPGPolicy

    def __init__(
        self,
        policy: str | type[DTDPGPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 1e-3,
        buffer_size: int = 1_000_000,
        learning_starts: int = 100,
        batch_size: int = 256,
        tau: float = 0.005,
        gamma: float = 0.99,
        train_freq: int | tuple[int, str] = 1,
        gradient_steps: int = 1,
        action_noise: ActionNoise | None = None,
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        optimize_memory_usage: bool = False,
        n_steps: int = 1,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        phases: Iterable[Phase | Mapping[str, Any]] | None = None,
        curriculum_save_path: str | None = None,
        reinitialize_at_transfer: bool = False,
        lean: bool = True,
        backprop: bool = True,
        _init_setup_model: bool = True,
    ):
        settings: dict[str, Any] = dict(
            learning_rate=learning_rate,
            buffer_size=buffer_size,
            learning_starts=learning_starts,
            batch_size=batch_size,
            tau=tau,
            gamma=gamma,
            train_freq=train_freq,
            gradient_steps=gradient_steps,
            n_steps=n_steps,
            policy_kwargs=policy_kwargs,
        )
        check_off_policy_settings("DTDPG", settings)
        settings["policy_kwargs"] = None if policy_kwargs is None else dict(policy_kwargs)  # DDPG adds n_critics to it
        check_switches(
            "DTDPG",
            dict(
                zip(_SWITCHES, (optimize_memory_usage, reinitialize_at_transfer, lean, backprop), strict=True),
            ),
        )
        check_folder("DTDPG", "curriculum_save_path", curriculum_save_path)
        check_folder("DTDPG", "tensorboard_log", tensorboard_log)
        super().__init__(
            policy=policy,
            env=env,
            action_noise=action_noise,
            replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs,
            optimize_memory_usage=optimize_memory_usage,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=False,
            **settings,
        )
        self.curriculum_save_path = curriculum_save_path
        self.lean = lean
        self.backprop = backprop
        self.reinitialize_at_transfer = reinitialize_at_transfer
        # Set by CurriculumTransferCallback at the first learn(), then saved with the model
        self.curriculum_state: dict[str, Any] | None = None
        if phases is not None:
            self.phases = parse_phases(phases)
        else:
            self.phases = default_curriculum(self.env)  # the env's own, or one phase
            if action_noise is not None:  # the user's noise is used as is: the default phases leave it alone
                self.phases = [dataclasses.replace(p, sigma=None, final_sigma=None, decay_episodes=None) for p in self.phases]

        if self.env is not None:  # refused here, not at the first learn()
            check_env_phases(self.phases, self.env)
            check_action_noise("DTDPG", action_noise, self.action_space.shape)
        schedule = self.phases[0].noise_schedule()
        # No env when load() builds the model: the saved action noise is restored afterwards
        if self.action_noise is None and schedule is not None and self.env is not None:
            self.action_noise = decaying_noise(self.action_space.shape, *schedule)
        # Without a buffer class given, the model picks one for its returns, and picks again when load() is given
        # other n_steps or gamma (as SB3's own pick follows the model's n_steps and gamma)
        self._buffer_follows_returns = self.replay_buffer_class is None
        if self._buffer_follows_returns:
            _check_buffer_returns("DTDPG", self.replay_buffer_kwargs, {"n_steps": self.n_steps, "gamma": self.gamma})
            self._pick_replay_buffer()

        if _init_setup_model:
            self._setup_model()

    def _pick_replay_buffer(self) -> None:
        """The replay buffer for the model's returns: the relabelling one when a later phase relabels the replay, the
        fast n-step one for n-step returns of ``Box`` observations (SB3's ``NStepReplayBuffer``, sampled faster with
        the same numbers), else SB3's pick."""
        kwargs = {k: v for k, v in self.replay_buffer_kwargs.items() if k not in ("n_steps", "gamma")}
        if any(phase.replay_handling == "relabel" for phase in self.phases[1:]):
            self.replay_buffer_class, returns = reward_components_buffer(self.n_steps, self.gamma)
        elif self.n_steps > 1 and isinstance(self.observation_space, spaces.Box):
            self.replay_buffer_class, returns = FastNStepReplayBuffer, {"n_steps": self.n_steps, "gamma": self.gamma}
        else:
            self.replay_buffer_class, returns = None, {}
        self.replay_buffer_kwargs = {**kwargs, **returns}

    def _setup_model(self) -> None:
        if getattr(self, "_buffer_follows_returns", False):  # False in models saved before it was recorded
            self._pick_replay_buffer()
        self._build_model()
        if self.batch_size < 2 and any(isinstance(module, th.nn.BatchNorm1d) for module in self.policy.modules()):
            raise ValueError(
                f"{type(self).__name__}: batch_size must be at least 2 with batch normalisation (the policy's actor_norm "
                f"or critic_norm 'batch'; a batch of one has no variance), got {self.batch_size}"
            )

    def _build_model(self) -> None:
        configured_n_step = (
            self.n_steps > 1
            and self.replay_buffer_class is not None
            and issubclass(self.replay_buffer_class, NStepReplayBuffer)
            and self.replay_buffer_kwargs.get("n_steps") == self.n_steps
        )
        if not configured_n_step:
            super()._setup_model()
            return
        # SB3 warns that n_steps is ignored whenever a buffer class is given, also when the class is an n-step buffer
        # set up with these n_steps (SB3's own, picked before a save, or the relabelling one): the returns are set
        # up, so the warning would be wrong. SB3's set-up reads n_steps only to choose a buffer class and to warn:
        # with the class given, it builds the same model with n_steps set aside for the call
        n_steps, self.n_steps = self.n_steps, 1
        try:
            super()._setup_model()
        finally:
            self.n_steps = n_steps

    def set_random_seed(self, seed: int | None = None) -> None:
        """
        Seed the random generators (SB3's ``set_random_seed``), except while :meth:`reinitialize` builds new
        networks: then the generators go on from where they are.

        :param seed: the seed (None: no seeding)
        """
        if not getattr(self, "_drawing_new_networks", False):
            super().set_random_seed(seed)

    def reinitialize(self) -> None:
        """
        Re-create the networks (actor, critic and their targets) from scratch, with fresh optimisers: the
        ablation of the transfer (``reinitialize_at_transfer=True``).

        The replay buffer, the action noise, the counters and the curriculum state are kept. The global random
        generators are not re-seeded (re-seeding would replay their streams): the new weights are drawn from
        where the streams are. The policy is left in evaluation mode, the mode SB3 collects rollouts in.
        """
        self._drawing_new_networks = True  # _setup_model() seeds the generators: see set_random_seed()
        try:
            self._setup_model()
        finally:
            self._drawing_new_networks = False
        self.policy.set_training_mode(False)

    def learn(
        self: SelfDTDPG,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 4,
        tb_log_name: str = "DTDPG",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfDTDPG:
        """
        SB3's ``learn`` with the curriculum (:class:`~sb3_dtdpg.common.callbacks.CurriculumTransferCallback`) added
        before the given callbacks. Mission figures are logged by passing
        :class:`sb3_dtdpg.MissionLoggerCallback` as a callback.

        :param total_timesteps: the number of env steps to train for (a positive integer, or a float of one: ``1e5``)
        :param callback: callback(s) called at every step
        :param log_interval: episodes between log dumps
        :param tb_log_name: the name of the run for TensorBoard logging
        :param reset_num_timesteps: whether or not to reset the current timestep number (used in logging)
        :param progress_bar: display a progress bar using tqdm and rich
        :return: the trained model
        """
        total_timesteps = check_total_timesteps(total_timesteps)
        check_log_interval(log_interval)
        check_callback(callback)
        user_callbacks: list[BaseCallback] = []
        for user_callback in callback if isinstance(callback, list) else [callback]:
            if user_callback is not None:
                if not isinstance(user_callback, BaseCallback):
                    user_callback = ConvertCallback(user_callback)
                user_callbacks.append(user_callback)
        if any(isinstance(c, CurriculumTransferCallback) for c in _all_callbacks(user_callbacks)):
            raise ValueError(
                "callback: DTDPG runs its own CurriculumTransferCallback (from its phases); a second one would count "
                "every step twice: give the phases to DTDPG(phases=...) or DTDPG.load(..., phases=...) instead"
            )
        curriculum = CurriculumTransferCallback(
            self.phases,
            save_path=self.curriculum_save_path,
            reinitialize_at_transfer=self.reinitialize_at_transfer,
            verbose=self.verbose,
            eval_callbacks=_curriculum_evaluations(user_callbacks),
        )
        callbacks: list[BaseCallback] = [curriculum, *user_callbacks]
        return super().learn(
            total_timesteps=total_timesteps,
            callback=CallbackList(callbacks),
            log_interval=log_interval,
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
        )

    # The env settings the model was trained with travel in the zip (sb3_dtdpg.env_settings): a mismatched env
    # is refused at load/set_env with the settings to use, instead of a bare space mismatch (or, NOMA vs OMA,
    # nothing at all). set_env compares with the model's current env, a model never saved included.
    def save(self, path: Any, exclude: Iterable[str] | None = None, include: Iterable[str] | None = None) -> None:
        env_settings.record(self)
        super().save(path, exclude=exclude, include=include)

    def _setup_learn(self, total_timesteps: int, callback: MaybeCallback = None, *args: Any, **kwargs: Any) -> Any:
        # SB3 wraps the noise in one copy per env, once: a model loaded onto another number of envs gets copies for
        # these (the decay schedule, shared by the copies, goes on)
        noise = self.action_noise
        if isinstance(noise, VectorizedActionNoise) and self.env is not None and len(noise.noises) != self.env.num_envs:
            base = noise.noises[0]
            base.reset()
            self.action_noise = VectorizedActionNoise(base, self.env.num_envs) if self.env.num_envs > 1 else base
        return super()._setup_learn(total_timesteps, callback, *args, **kwargs)

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        env_settings.check_settings(env_settings.trained_settings(self), env)
        super().set_env(env, force_reset=force_reset)

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "curriculum_save_path"]

    def load_replay_buffer(self, path: Any, truncate_last_traj: bool = True) -> None:
        """
        SB3's ``load_replay_buffer``, refusing a buffer of another observation or action space or another number of
        envs (it would fail at the next stored transition with a bare broadcast error), or one computing returns of
        other ``n_steps`` or ``gamma`` than the model's (its targets would follow the buffer's); the model's buffer is
        then kept.

        :param path: the pickled replay buffer
        :param truncate_last_traj: see SB3 (``HerReplayBuffer`` only)
        :raises ValueError: naming what differs
        """
        previous = getattr(self, "replay_buffer", None)
        super().load_replay_buffer(path, truncate_last_traj)
        buffer = self.replay_buffer
        compared = [
            ("observation space", buffer.observation_space, self.observation_space),
            ("action space", buffer.action_space, self.action_space),
            ("number of envs", buffer.n_envs, self.n_envs if self.env is not None else buffer.n_envs),
        ]
        if getattr(self, "_buffer_follows_returns", False):
            # a buffer that computes returns samples their discounts, which the targets use instead of the model's
            compared.append(("n_steps", getattr(buffer, "n_steps", 1), self.n_steps))
            if hasattr(buffer, "gamma"):
                compared.append(("gamma", buffer.gamma, self.gamma))
        differences = [f"{name} {got} (the model's: {want})" for name, got, want in compared if got != want]
        if differences:
            self.replay_buffer = previous
            raise ValueError(f"the replay buffer {path} does not fit this model: {'; '.join(differences)}")

    @classmethod
    def load(cls, path: Any, env: GymEnv | None = None, device: Any = "auto", custom_objects: Any = None, **kwargs: Any):
        # settings given as keyword arguments replace the saved ones: the constructor's checks hold for them too
        # (custom_objects are not checked: they stand in for objects that cannot be unpickled, e.g. learning_rate=0)
        if kwargs.get("learning_rate") == 0 and not isinstance(kwargs["learning_rate"], bool):  # a frozen model, as SB3
            custom_objects = {**(custom_objects or {}), "learning_rate": kwargs.pop("learning_rate")}
        check_off_policy_settings("DTDPG.load", kwargs)
        check_switches("DTDPG.load", {name: kwargs[name] for name in _SWITCHES if name in kwargs})
        for folder in ("curriculum_save_path", "tensorboard_log"):
            check_folder("DTDPG.load", folder, kwargs.get(folder))
        if kwargs.get("phases") is not None:
            kwargs["phases"] = parse_phases(kwargs["phases"])
        kwargs.setdefault("curriculum_save_path", None)  # zips saved before it was excluded from saving carry one
        data = load_from_zip_file(path, device="cpu", custom_objects=custom_objects, load_data=True)[0] or {}
        if env is not None:
            env_settings.check_settings(data.get("env_settings"), env, f"the model {path}")
        if kwargs.get("action_noise") is not None and data.get("action_space") is not None:
            check_action_noise("DTDPG.load", kwargs["action_noise"], data["action_space"].shape)
        # a model saved before its buffer choice was recorded keeps its buffer (the constructor's flag would stand);
        # a buffer class given here is used (None: the model picks one for its returns, as when it was built)
        if "replay_buffer_class" in kwargs:
            kwargs["_buffer_follows_returns"] = kwargs["replay_buffer_class"] is None
        kwargs.setdefault("_buffer_follows_returns", data.get("_buffer_follows_returns", False))
        if kwargs["_buffer_follows_returns"] and "replay_buffer_kwargs" in kwargs:
            returns = {name: kwargs.get(name, data.get(name)) for name in ("n_steps", "gamma")}
            _check_buffer_returns("DTDPG.load", kwargs["replay_buffer_kwargs"], returns)
        saved = data.get("replay_buffer_kwargs") or {}
        kept = [f"{k}={saved[k]!r}" for k in ("n_steps", "gamma") if k in saved and kwargs.get(k, saved[k]) != saved[k]]
        if not kwargs["_buffer_follows_returns"] and "replay_buffer_kwargs" not in kwargs and kept:
            warnings.warn(
                f"DTDPG.load: the replay buffer of {path} keeps {', '.join(kept)} (a model saved before its buffer "
                "followed the model's returns, or a buffer class given by hand): pass replay_buffer_kwargs to change them"
            )
        return super().load(path, env=env, device=device, custom_objects=custom_objects, **kwargs)


def _check_buffer_returns(owner: str, buffer_kwargs: Mapping[str, Any] | None, returns: Mapping[str, Any]) -> None:
    """
    :param owner: where the settings are given, for the message
    :param buffer_kwargs: the ``replay_buffer_kwargs`` given
    :param returns: the model's ``n_steps`` and ``gamma``, from which a buffer that follows the returns sets its own
    :raises ValueError: a value of ``buffer_kwargs`` that differs from the model's (it would be dropped)
    """
    for name, value in returns.items():
        given = (buffer_kwargs or {}).get(name, value)
        if given != value:
            raise ValueError(
                f"{owner}: replay_buffer_kwargs[{name!r}] = {given!r} differs from the model's {name} = {value!r}: "
                f"the replay buffer's returns follow the model's n_steps and gamma, pass {name}={given!r} instead"
            )


#: The constructor's on/off settings
_SWITCHES = ("optimize_memory_usage", "reinitialize_at_transfer", "lean", "backprop")


def _all_callbacks(callbacks: Iterable[BaseCallback]) -> Iterator[BaseCallback]:
    """
    :param callbacks: callbacks given to ``learn``
    :return: each of them and those they call: a ``CallbackList``'s, an ``EventCallback``'s ``callback``
        (``EveryNTimesteps``) and an ``EvalCallback``'s ``callback_on_new_best`` and ``callback_after_eval``, each once
    """
    seen: set[int] = set()
    pending = list(callbacks)
    while pending:
        callback = pending.pop(0)
        if id(callback) in seen:
            continue
        seen.add(id(callback))
        yield callback
        inner = list(callback.callbacks) if isinstance(callback, CallbackList) else []
        inner += [getattr(callback, name, None) for name in ("callback", "callback_on_new_best", "callback_after_eval")]
        pending = [c for c in inner if isinstance(c, BaseCallback)] + pending


def _curriculum_evaluations(callbacks: list[BaseCallback]) -> list[EvalCallback]:
    """
    The ``EvalCallback`` objects (also inside other callbacks, :func:`_all_callbacks`) whose eval env follows the
    curriculum's reward phase. Optuna's trial callbacks (the RL Zoo's ``TrialEvalCallback``, which has a ``trial``)
    keep their env's reward: a search compares trials on one objective, also those that never reach the last phase.
    """
    return [c for c in _all_callbacks(callbacks) if isinstance(c, EvalCallback) and not hasattr(c, "trial")]
