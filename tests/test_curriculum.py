"""CurriculumTransferCallback and MissionLoggerCallback on a tiny env with reward phases (tests/phased_env.py)."""

import copy
import os
import re

import numpy as np
import pytest
import torch as th
from phased_env import PHASE_WEIGHTS, PhasedPointEnv
from stable_baselines3 import DDPG, TD3
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.utils import set_random_seed

from noma_radiomap.rewards import REWARD_COMPONENTS
from sb3_dtdpg.common.buffers import RewardComponentsNStepReplayBuffer, RewardComponentsReplayBuffer
from sb3_dtdpg.common.callbacks import CurriculumTransferCallback
from sb3_dtdpg.common.noise import noise_sigma
from sb3_dtdpg.common.phases import Phase
from sb3_dtdpg.missions import MissionLoggerCallback

try:
    from sb3_dtdpg.dtdpg import DTDPG
except ImportError:  # pragma: no cover - until the algorithm lands
    DTDPG = None

ALGOS = [DDPG, pytest.param(DTDPG, marks=pytest.mark.skipif(DTDPG is None, reason="DTDPG not available"))]

# Fixed mission the robot cannot finish in 20 steps (distance 1.13 > 20 x 0.03): every episode lasts exactly
# 20 steps and resets draw nothing, which makes budgets land on known steps and runs comparable step by step.
LONG_EPISODES = {"starts": [[0.1, 0.1]], "destinations": [[0.9, 0.9]], "v_max": 0.03}
# Arrival on the first step: every episode is a 1-step success.
ALWAYS_SUCCESS = {"starts": [[0.5, 0.5]], "destinations": [[0.5, 0.55]], "arrival_radius": 0.5}

W = {phase: np.array([weights[k] for k in REWARD_COMPONENTS]) for phase, weights in PHASE_WEIGHTS.items()}


def two_phases(**mqi_kwargs):
    return [
        Phase("destination", n_episodes=3, sigma=0.5, final_sigma=0.1),
        Phase("mqi", **{"sigma": 0.3, "final_sigma": 0.05, "decay_episodes": 10, **mqi_kwargs}),
    ]


def make_env(n_envs=1, seed=0, **env_kwargs):
    return make_vec_env(PhasedPointEnv, n_envs=n_envs, seed=seed, env_kwargs=env_kwargs or LONG_EPISODES)


def make_model(algo, env, phases, save_path=None, reinitialize=False, **kwargs):
    """A tiny model; returns it with the curriculum callback to pass to learn() (None: DTDPG adds its own)."""
    kwargs = {"learning_starts": 10, "batch_size": 16, "policy_kwargs": {"net_arch": [16]}, "seed": 0, **kwargs}
    if algo is DTDPG:
        model = DTDPG(
            "MlpPolicy", env, phases=phases, curriculum_save_path=save_path, reinitialize_at_transfer=reinitialize, **kwargs
        )
        return model, None
    model = algo("MlpPolicy", env, **kwargs)
    return model, CurriculumTransferCallback(phases, save_path=save_path, reinitialize_at_transfer=reinitialize)


def learn(model, curriculum, steps, callbacks=(), **kwargs):
    return model.learn(steps, callback=[c for c in (curriculum, *callbacks) if c is not None], **kwargs)


def policy_state(model):
    return {k: v.detach().clone() for k, v in model.policy.state_dict().items()}


def states_equal(a, b):
    return a.keys() == b.keys() and all(th.equal(a[k], b[k]) for k in a)


class Probe(BaseCallback):
    """Records, at every step, what the step did and the state right after the curriculum callback ran."""

    def __init__(self, snapshot_params=False):
        super().__init__()
        self.snapshot_params = snapshot_params
        self.steps = []
        self.before = None

    def _on_rollout_start(self) -> None:
        # With train_freq=1 the next on_step sees the networks as they are now (the gradient step came before)
        if self.snapshot_params:
            self.before = policy_state(self.model)

    def _on_step(self) -> bool:
        state = self.model.curriculum_state
        record = {
            "t": self.num_timesteps,
            "rewards": np.array(self.locals["rewards"], dtype=np.float64),
            "components": np.array([[i["reward_components"][k] for k in REWARD_COMPONENTS] for i in self.locals["infos"]]),
            "dones": np.array(self.locals["dones"]),
            "infos": copy.deepcopy(self.locals["infos"]),
            "phase_index": state["phase_index"],
            "env_phase": self.training_env.get_attr("reward_phase")[0],
            "sigma": noise_sigma(self.model.action_noise),
        }
        if self.snapshot_params and len(state["history"]) > 1 and state["history"][-1]["start_timestep"] == self.num_timesteps:
            record["before"], record["after"] = self.before, policy_state(self.model)
        self.steps.append(record)
        return True

    def at(self, t):
        return next(step for step in self.steps if step["t"] == t)


@pytest.mark.parametrize("algo", ALGOS)
def test_switches_phase_env_reward_and_noise_at_configured_episode(algo):
    model, curriculum = make_model(algo, make_env(), two_phases())
    probe = Probe()
    learn(model, curriculum, 100, [probe])

    state = model.curriculum_state
    assert state["history"][0] == {
        "phase": "destination",
        "reward_phase": "destination",
        "start_timestep": 0,
        "end_timestep": 60,
        "episodes": 3,
        "timesteps": 60,
        "reason": "episode budget",
    }
    assert state["phase_index"] == 1 and state["episodes_in_phase"] == 2 and state["timesteps_in_phase"] == 40
    # Each step's reward is the reward of the phase it was taken in: destination for the 3 episodes, then mqi
    for step in probe.steps:
        phase = "destination" if step["t"] <= 60 else "mqi"
        np.testing.assert_allclose(step["rewards"], step["components"] @ W[phase], rtol=1e-6)
        assert step["phase_index"] == (0 if step["t"] < 60 else 1)
        assert step["env_phase"] == ("destination" if step["t"] < 60 else "mqi")
    # Linear decay within phase 1 (3 episodes), re-armed at the transfer to phase 2's schedule, whose first episode
    # starts right after it (the end of phase 1's last episode does not count in phase 2's schedule)
    for t, episode in ((1, 0), (21, 1), (59, 2)):
        assert probe.at(t)["sigma"] == pytest.approx(0.5 + (0.1 - 0.5) * episode / 3)
    assert probe.at(60)["sigma"] == pytest.approx(0.3)
    assert probe.at(61)["sigma"] == pytest.approx(0.3) and probe.at(80)["sigma"] == pytest.approx(0.3)
    assert probe.at(81)["sigma"] == pytest.approx(0.3 + (0.05 - 0.3) / 10)


@pytest.mark.parametrize("reinitialize", [False, True])
@pytest.mark.parametrize("algo", ALGOS)
def test_networks_carry_over_or_reinitialise_and_checkpoints_load(algo, reinitialize, tmp_path):
    model, curriculum = make_model(algo, make_env(), two_phases(), save_path=tmp_path, reinitialize=reinitialize)
    probe = Probe(snapshot_params=True)
    if reinitialize and algo is not DTDPG:
        # Re-initialising needs the model's public reinitialize() (DTDPG's), not SB3's private _setup_model()
        with pytest.raises(ValueError, match="needs a model with reinitialize"):
            learn(model, curriculum, 80, [probe])
        return
    learn(model, curriculum, 80, [probe])

    transfer = probe.at(60)
    before, after = transfer["before"], transfer["after"]
    if algo is DTDPG:
        assert any("running_mean" in key for key in before)  # the batch-norm statistics are compared too
    assert states_equal(before, after) is not reinitialize
    # theta_X of Algorithm 1: the model at the end of phase 1, saved atomically (no temporary file left)
    assert sorted(os.listdir(tmp_path)) == ["phase_0_destination.zip", "phase_1_mqi.zip"]
    loaded = type(model).load(tmp_path / "phase_0_destination.zip", env=make_env(), device="cpu")
    assert states_equal(policy_state(loaded), before)
    assert loaded.curriculum_state["phase_index"] == 0 and loaded.curriculum_state["finished"]
    # The last phase is saved when learn() ends
    final = type(model).load(tmp_path / "phase_1_mqi.zip", env=make_env(), device="cpu")
    assert states_equal(policy_state(final), policy_state(model))
    # After a re-initialisation the algorithm's aliases point to the new networks and training went on with them
    assert model.actor is model.policy.actor and model.critic_target is model.policy.critic_target
    assert not states_equal(after, policy_state(model))


@pytest.mark.parametrize("algo", ALGOS)
def test_training_from_phase_checkpoint_enters_next_phase(algo, tmp_path):
    model, curriculum = make_model(algo, make_env(), two_phases(), save_path=tmp_path)
    learn(model, curriculum, 60)
    env = make_env()
    loaded = type(model).load(tmp_path / "phase_0_destination.zip", env=env, device="cpu")
    _, curriculum = make_model(algo, env, two_phases())
    probe = Probe()
    learn(loaded, curriculum, 20, [probe], reset_num_timesteps=False)
    assert loaded.curriculum_state["phase_index"] == 1
    assert probe.steps[0]["env_phase"] == "mqi" and probe.steps[0]["sigma"] == pytest.approx(0.3)
    np.testing.assert_allclose(probe.steps[0]["rewards"], probe.steps[0]["components"] @ W["mqi"], rtol=1e-6)


@pytest.mark.parametrize("algo", ALGOS)
def test_a_second_run_into_the_same_folder_is_refused_not_written_over_the_first(algo, tmp_path):
    # Two fresh curricula into one folder: the second overwrote the first's phase_*.zip
    model, curriculum = make_model(algo, make_env(), two_phases(), save_path=tmp_path)
    learn(model, curriculum, 80)
    first = {path.name: path.read_bytes() for path in tmp_path.iterdir()}
    assert sorted(first) == ["phase_0_destination.zip", "phase_1_mqi.zip"]
    other, curriculum = make_model(algo, make_env(seed=1), two_phases(), save_path=tmp_path, seed=1)
    message = f"save_path (DTDPG: curriculum_save_path) {str(tmp_path)!r} already holds phase_0_destination.zip, "
    with pytest.raises(ValueError, match=re.escape(message + "phase_1_mqi.zip of an earlier curriculum run")):
        learn(other, curriculum, 80)
    assert other.num_timesteps == 0 and {path.name: path.read_bytes() for path in tmp_path.iterdir()} == first
    # the run itself goes on writing there: another learn(), or a model loaded from its phase file
    learn(model, curriculum if algo is DTDPG else CurriculumTransferCallback(two_phases(), save_path=tmp_path), 20)
    assert (tmp_path / "phase_1_mqi.zip").read_bytes() != first["phase_1_mqi.zip"]
    env = make_env()
    loaded = type(model).load(tmp_path / "phase_0_destination.zip", env=env, device="cpu")
    if algo is DTDPG:
        loaded.curriculum_save_path = str(tmp_path)
    learn(loaded, None if algo is DTDPG else CurriculumTransferCallback(two_phases(), save_path=tmp_path), 20)
    assert loaded.curriculum_state["phase_index"] == 1
    # ... and the second run in a folder of its own
    if algo is DTDPG:
        other.curriculum_save_path = str(tmp_path / "second")
    learn(other, None if algo is DTDPG else CurriculumTransferCallback(two_phases(), save_path=tmp_path / "second"), 80)
    assert sorted(os.listdir(tmp_path / "second")) == ["phase_0_destination.zip", "phase_1_mqi.zip"]


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("handling", ["keep", "relabel", "clear"])
@pytest.mark.parametrize("n_steps", [1, 3])
def test_replay_handling(algo, handling, n_steps):
    if n_steps == 1:
        buffer_kwargs = {"replay_buffer_class": RewardComponentsReplayBuffer}
    else:
        buffer_kwargs = {
            "replay_buffer_class": RewardComponentsNStepReplayBuffer,
            "replay_buffer_kwargs": {"n_steps": n_steps, "gamma": 0.99},
        }
    model, curriculum = make_model(algo, make_env(), two_phases(replay_handling=handling), **buffer_kwargs)
    learn(model, curriculum, 100)
    buffer = model.replay_buffer
    stored = buffer.rewards[: buffer.pos, 0].astype(np.float64)
    # Recomputed from the stored components with the env's weights, independently of buffer.relabel()
    components = buffer.reward_components[: buffer.pos, 0]
    mqi, destination = components @ W["mqi"], components @ W["destination"]
    assert not np.allclose(mqi, destination)  # the phases' rewards differ on these transitions
    if handling == "keep":
        assert buffer.pos == 100
        np.testing.assert_allclose(stored[:60], destination[:60], rtol=1e-6)
        np.testing.assert_allclose(stored[60:], mqi[60:], rtol=1e-6)
    else:
        # "clear" keeps the transfer step's own transition (the gradient step after it needs data)
        assert buffer.pos == (100 if handling == "relabel" else 41)
        np.testing.assert_allclose(stored, mqi, rtol=1e-6)


def test_clear_with_plain_replay_buffer():
    model, curriculum = make_model(TD3, make_env(), two_phases(replay_handling="clear"))
    learn(model, curriculum, 100)
    assert type(model.replay_buffer) is ReplayBuffer and model.replay_buffer.size() == 41


@pytest.mark.parametrize("algo", ALGOS)
def test_early_transfer_on_success_rate(algo):
    phases = [Phase("destination", n_episodes=50, success_threshold=0.75, success_window=4, sigma=0.5), Phase("mqi")]
    model, curriculum = make_model(algo, make_env(**ALWAYS_SUCCESS), phases)
    learn(model, curriculum, 10)
    history = model.curriculum_state["history"]
    assert history[0]["reason"] == "success rate" and history[0]["end_timestep"] == 4 and history[0]["episodes"] == 4
    # Never successful: the episode budget ends the phase
    phases = [Phase("destination", n_episodes=3, success_threshold=0.5, success_window=2), Phase("mqi")]
    model, curriculum = make_model(algo, make_env(), phases)
    learn(model, curriculum, 70)
    assert model.curriculum_state["history"][0]["reason"] == "episode budget"
    assert model.curriculum_state["recent_successes"] == []


def test_timestep_budget_and_vectorized_env():
    env = make_env(n_envs=2)
    phases = [Phase("destination", n_episodes=3, sigma=0.5), Phase("mqi", n_timesteps=30, sigma=0.2), Phase("combined")]
    model, curriculum = make_model(DDPG, env, phases)
    probe = Probe()
    learn(model, curriculum, 120, [probe])
    history = model.curriculum_state["history"]
    # 2 envs finish together every 20 vector steps: the 3-episode budget is spent with 4 episodes at step 80
    assert history[0]["end_timestep"] == 80 and history[0]["episodes"] == 4
    assert history[1]["end_timestep"] == 110 and history[1]["timesteps"] == 30
    assert [h["phase"] for h in history] == ["destination", "mqi", "combined"]
    assert probe.at(110)["env_phase"] == "combined" and probe.at(108)["env_phase"] == "mqi"


def test_last_phase_budget_stops_training(tmp_path):
    phases = [Phase("destination", n_episodes=2), Phase("mqi", n_episodes=1)]
    model, curriculum = make_model(DDPG, make_env(), phases, save_path=tmp_path)
    learn(model, curriculum, 1000)
    assert model.num_timesteps == 60 and model.curriculum_state["finished"]
    assert sorted(os.listdir(tmp_path)) == ["phase_0_destination.zip", "phase_1_mqi.zip"]
    with pytest.warns(UserWarning, match="curriculum is over"):
        learn(model, CurriculumTransferCallback(phases), 100, reset_num_timesteps=False)
    assert model.num_timesteps == 61


class ReseedAt(BaseCallback):
    """Re-seed the global RNGs when a rollout starts at a given step (where the other run is saved and loaded)."""

    def __init__(self, timestep, seed):
        super().__init__()
        self.timestep, self.seed = timestep, seed

    def _on_rollout_start(self) -> None:
        if self.model.num_timesteps == self.timestep:
            set_random_seed(self.seed)

    def _on_step(self) -> bool:
        return True


@pytest.mark.parametrize("algo", ALGOS)
def test_save_load_continue_matches_uninterrupted_run(algo, tmp_path):
    """
    SB3 saves neither the global RNG states nor the env, so both runs re-seed the global RNGs at the interruption
    (an episode boundary of a mission whose reset draws nothing); everything else must come from what
    model.save / save_replay_buffer keep: networks, optimizers, action noise schedule and the curriculum state.
    """
    total, cut, reseed = 120, 40, 123  # the transfer (step 60) happens after the interruption

    def run(interrupt, drop_state=False):
        model, curriculum = make_model(
            algo, make_env(), two_phases(replay_handling="relabel"), replay_buffer_class=RewardComponentsReplayBuffer
        )
        if interrupt is None:
            learn(model, curriculum, total, [ReseedAt(cut, reseed)])
            return model
        learn(model, curriculum, cut)
        if interrupt == "save_load":
            model.save(tmp_path / "model.zip")
            model.save_replay_buffer(tmp_path / "buffer.pkl")
            env = make_env(seed=1)
            model = type(model).load(tmp_path / "model.zip", env=env, device="cpu")
            model.load_replay_buffer(tmp_path / "buffer.pkl")
            if drop_state:
                model.curriculum_state = None
        _, curriculum = make_model(algo, model.get_env(), two_phases(replay_handling="relabel"))
        set_random_seed(reseed)
        learn(model, curriculum, total - cut, reset_num_timesteps=False)
        return model

    reference = run(None)
    assert reference.curriculum_state["history"][0]["end_timestep"] == 60
    for interrupt in ("repeat_learn", "save_load"):
        model = run(interrupt)
        assert model.num_timesteps == total
        assert model.curriculum_state == reference.curriculum_state
        assert noise_sigma(model.action_noise) == noise_sigma(reference.action_noise)
        assert states_equal(policy_state(model), policy_state(reference)), interrupt
        np.testing.assert_array_equal(model.replay_buffer.rewards, reference.replay_buffer.rewards)
    # The comparison can fail: without the saved curriculum state the resumed run restarts phase 1 and diverges
    restarted = run("save_load", drop_state=True)
    assert restarted.curriculum_state["history"][0]["end_timestep"] == 100
    assert not states_equal(policy_state(restarted), policy_state(reference))


class SaveAt(BaseCallback):
    """Saves the model and its replay buffer at step ``t``, after the curriculum ran (as a CheckpointCallback would)."""

    def __init__(self, t, folder):
        super().__init__()
        self.t, self.folder = t, folder

    def _on_step(self) -> bool:
        if self.num_timesteps == self.t:
            self.model.save(self.folder / "model.zip")
            self.model.save_replay_buffer(self.folder / "buffer.pkl")
        return True


@pytest.mark.parametrize("algo", ALGOS)
def test_a_model_saved_at_the_transfer_step_relabels_its_replay_when_it_resumes(algo, tmp_path):
    # The relabelling waits until SB3 has stored the transfer step's transitions: a save in that step (e.g. a
    # CheckpointCallback whose save_freq is the phase's budget) held the old phase's rewards, and resumed on them
    phases = two_phases(replay_handling="relabel")
    model, curriculum = make_model(algo, make_env(), phases, replay_buffer_class=RewardComponentsReplayBuffer)
    learn(model, curriculum, 61, [SaveAt(60, tmp_path)])
    reference = model.replay_buffer
    resumed = type(model).load(tmp_path / "model.zip", env=make_env(), device="cpu")
    resumed.load_replay_buffer(tmp_path / "buffer.pkl")
    assert resumed.curriculum_state["phase_index"] == 1 and resumed.replay_buffer.pos == 59
    _, curriculum = make_model(algo, resumed.get_env(), phases)
    learn(resumed, curriculum, 1, reset_num_timesteps=False)
    np.testing.assert_array_equal(resumed.replay_buffer.rewards[:59], reference.rewards[:59])
    components = reference.reward_components[:59, 0]
    np.testing.assert_allclose(reference.rewards[:59, 0], components @ W["mqi"], rtol=1e-6)
    assert "pending_replay" not in resumed.curriculum_state and "pending_replay" not in model.curriculum_state


def test_the_reinitialisation_switch_of_the_callback_is_a_bool():
    # "no" counted as on: the ablation re-created the networks at every transfer
    with pytest.raises(
        ValueError, match=r"CurriculumTransferCallback: reinitialize_at_transfer must be True or False, got 'no'"
    ):
        CurriculumTransferCallback(two_phases(), reinitialize_at_transfer="no")


def test_resume_with_other_phases_is_refused():
    model, curriculum = make_model(DDPG, make_env(), two_phases())
    learn(model, curriculum, 20)
    other = [Phase("destination", n_episodes=3), Phase("combined")]
    with pytest.raises(ValueError, match="combined"):
        learn(model, CurriculumTransferCallback(other), 20, reset_num_timesteps=False)


@pytest.mark.parametrize(
    ("phases", "env_id", "match"),
    [
        (two_phases(replay_handling="relabel"), None, "RewardComponentsReplayBuffer"),
        ([Phase("destination", n_episodes=1), Phase("nope")], None, "'nope'"),
        (two_phases(), "Pendulum-v1", "set_reward_phase"),
    ],
)
def test_bad_setup_is_refused(phases, env_id, match):
    env = make_vec_env(env_id) if env_id else make_env()
    model = DDPG("MlpPolicy", env, policy_kwargs={"net_arch": [8]})
    with pytest.raises(ValueError, match=match):
        model.learn(10, callback=CurriculumTransferCallback(phases))


def test_success_rule_needs_is_success():
    env = make_vec_env("Pendulum-v1")
    phases = [Phase("swing", reward_phase=None, n_episodes=5, success_threshold=0.9), Phase("hold", reward_phase=None)]
    model = DDPG("MlpPolicy", env, learning_starts=1000, policy_kwargs={"net_arch": [8]})
    with pytest.raises(ValueError, match="is_success"):
        model.learn(200, callback=CurriculumTransferCallback(phases))


def test_works_without_reward_phases_and_creates_noise():
    env = make_vec_env("Pendulum-v1", n_envs=2)
    phases = [Phase("a", reward_phase=None, n_episodes=2, sigma=0.4), Phase("b", reward_phase=None, sigma=0.2)]
    model = TD3("MlpPolicy", env, learning_starts=1000, policy_kwargs={"net_arch": [8]})
    assert model.action_noise is None
    model.learn(600, callback=CurriculumTransferCallback(phases))
    assert model.curriculum_state["history"][0]["end_timestep"] == 400
    assert noise_sigma(model.action_noise) == pytest.approx(0.2)


def test_tensorboard_scalars(tmp_path):
    from tbparse import SummaryReader

    model, curriculum = make_model(DDPG, make_env(), two_phases(), tensorboard_log=str(tmp_path))
    probe = Probe()
    learn(model, curriculum, 100, [MissionLoggerCallback(), probe], log_interval=1)
    scalars = SummaryReader(str(tmp_path)).scalars
    by_tag = {tag: frame.sort_values("step") for tag, frame in scalars.groupby("tag")}
    assert list(by_tag["curriculum/phase"]["value"]) == [0, 0, 1, 1, 1]
    assert list(by_tag["curriculum/phase"]["step"]) == [20, 40, 60, 80, 100]
    # Logged at each episode end, before SB3 resets the noise: the scale of the episode that ended, except at the
    # transfer (step 60), logged after the re-arm
    np.testing.assert_allclose(by_tag["curriculum/noise_sigma"]["value"], [0.5, 0.5 - 0.4 / 3, 0.3, 0.3, 0.275], rtol=1e-6)
    # One episode per log dump: the mission scalars are that episode's figures
    ends = [step["infos"][0] for step in probe.steps if step["dones"][0]]
    np.testing.assert_allclose(by_tag["mission/mqi"]["value"], [info["mqi"] for info in ends], rtol=1e-6)
    np.testing.assert_allclose(by_tag["mission/outage_steps"]["value"], [info["outage_steps"].sum() for info in ends])
    assert list(by_tag["mission/mission_time"]["value"]) == [20] * 5
    assert list(by_tag["mission/success_rate"]["value"]) == [0] * 5
    # MQI = T_total - sum_u (T_u + lambda x outage_u), the robot never arriving (T_u = 20)
    np.testing.assert_allclose(
        by_tag["mission/mqi"]["value"], 100 - 20 - 2 * by_tag["mission/outage_steps"]["value"].to_numpy(), rtol=1e-6
    )


def test_mission_success_rate_is_rolling():
    env = make_vec_env(PhasedPointEnv, n_envs=1, seed=0, env_kwargs=ALWAYS_SUCCESS)
    model = DDPG("MlpPolicy", env, learning_starts=100, policy_kwargs={"net_arch": [8]})
    logger_cb = MissionLoggerCallback(stats_window_size=3)
    model.learn(5, callback=logger_cb)
    assert list(logger_cb.successes) == [True, True, True]


def test_the_episode_that_ends_the_last_phase_is_logged(tmp_path):
    # The curriculum stops training inside SB3's rollout, which then writes no logs for that step
    from stable_baselines3.common.logger import configure

    phases = [Phase("destination", n_episodes=2), Phase("mqi", n_episodes=1)]
    model, curriculum = make_model(DDPG, make_env(), phases)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    learn(model, curriculum, 1000, [MissionLoggerCallback()], log_interval=1)
    model.logger.close()
    import pandas as pd

    progress = pd.read_csv(tmp_path / "progress.csv")
    assert model.num_timesteps == 60 and len(progress) == 3 and progress["mission/mqi"].notna().all()
    assert list(progress["curriculum/episodes_in_phase"]) == [1, 0, 1]  # the transfer's row: after the re-arm


def test_the_env_reward_phases_of_the_phases_are_checked_when_the_model_is_made():
    with pytest.raises(ValueError, match=r"phase 'nope': reward_phase 'nope' is not a reward phase of the env \["):
        DTDPG("MlpPolicy", make_env(), phases=[Phase("destination", n_episodes=1), Phase("nope")])
    with pytest.raises(
        ValueError, match=r"the phases use the env reward phases \['destination', 'mqi'\].*no set_reward_phase"
    ):
        DTDPG("MlpPolicy", "Pendulum-v1", phases=two_phases())


def test_the_transfer_dip_windows_meet_at_the_transfer(monkeypatch):
    import pandas as pd

    from sb3_dtdpg.experiments import plots, reproduce

    # Episodes 1-5 trained the destination phase; the row of episode 5 is logged after the transfer (phase 1)
    curve = pd.Series(np.arange(1.0, 21.0), index=np.arange(1, 21))
    monkeypatch.setattr(plots, "transfer_episode", lambda log_dir: 5.0)
    monkeypatch.setattr(plots, "episode_curves", lambda log_dir, tags: {"mission/mqi": curve})
    dip = reproduce._dip(None, window=3)
    assert (dip["before"], dip["after"], dip["final"]) == (4.0, 7.0, 19.0)  # episodes 3-5, 6-8, 18-20


def test_a_model_loaded_without_its_noise_resumes_at_the_phases_scale_of_the_moment(tmp_path):
    import gymnasium as gym

    def env():
        return gym.make("Pendulum-v1", max_episode_steps=20)

    phase = Phase("train", reward_phase=None, sigma=0.5, final_sigma=0.1, decay_episodes=10)
    model = DTDPG("MlpPolicy", env(), phases=[phase], learning_starts=10, batch_size=16, seed=0)
    model.learn(400)  # 20 episodes: the decay is over
    assert noise_sigma(model.action_noise) == pytest.approx(0.1)
    model.save(tmp_path / "model.zip")
    resumed = DTDPG.load(tmp_path / "model.zip", env=env(), action_noise=None)
    resumed.learn(20, reset_num_timesteps=False)
    assert noise_sigma(resumed.action_noise) == pytest.approx(0.1)  # was 0.5: the decay restarted
