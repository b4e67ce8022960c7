"""The Python API's exact checkpoints: a model loaded from one of :class:`ExactCheckpointCallback`'s checkpoints and
trained to the same total gives the uninterrupted training's weights, bit for bit."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
from bitwise import same, saved_weights
from stable_baselines3 import DDPG, PPO
from stable_baselines3.common.noise import OrnsteinUhlenbeckActionNoise
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_dtdpg import DTDPG, ExactCheckpointCallback, load_checkpoint, preset
from sb3_dtdpg.common.checkpoints import checkpoint_files

TOTAL = 360  # 6 episodes of the small room's missions at most; the paper's settings learn from step 100


def _mission_env():
    return gym.make("NomaRadioMap-v0", scenario="small", observation="paper")


def _dtdpg(env):
    settings = preset("paper")
    destination, mqi = settings.pop("phases")
    phases = [
        dataclasses.replace(destination, n_episodes=2),
        dataclasses.replace(mqi, decay_episodes=3, replay_handling="relabel"),
    ]
    return DTDPG("MlpPolicy", env, seed=0, phases=phases, **settings)


def _ddpg(env):
    # SB3's own DDPG with OU noise, which SB3's learn resets when it starts
    noise = OrnsteinUhlenbeckActionNoise(np.zeros(1), np.full(1, 0.3))
    return DDPG("MlpPolicy", env, seed=0, learning_starts=100, action_noise=noise, policy_kwargs=dict(net_arch=[32, 32]))


def _short_pendulum():
    return gym.make("Pendulum-v1", max_episode_steps=50)


def _weights(model, folder):
    model.save(folder / "final.zip")
    return saved_weights(folder / "final.zip")


@pytest.mark.parametrize(
    ("build", "make_env", "algorithm"),
    [(_dtdpg, _mission_env, None), (_ddpg, lambda: gym.make("Pendulum-v1"), DDPG)],
    ids=["dtdpg", "sb3-ddpg"],
)
def test_training_resumed_from_an_exact_checkpoint_gives_the_uninterrupted_weights(tmp_path, build, make_env, algorithm):
    uninterrupted = build(make_env()).learn(TOTAL)
    expected = _weights(uninterrupted, tmp_path)
    folder = tmp_path / "checkpoints"
    saving = build(make_env()).learn(TOTAL, callback=ExactCheckpointCallback(30, str(folder)))
    assert same(_weights(saving, tmp_path), expected)  # saving changes nothing
    checkpoints = sorted(folder.glob("*_steps.zip"), key=lambda path: int(path.stem.split("_")[-2]))
    steps = [int(path.stem.split("_")[-2]) for path in checkpoints]
    # at the first episode end after every 30 steps
    if algorithm is None:
        # DT-DPG's: in the warm-up (learning from step 100), around its transfer (at the end of episode 2), and when
        # learn ended, at an episode's end
        assert steps[0] < 100 and steps[-1] == TOTAL and len(steps) >= 4
    else:
        assert steps == [200]  # DDPG's: at the end of Pendulum's first 200-step episode
    for checkpoint in [path for path, n in zip(checkpoints, steps, strict=True) if n < TOTAL]:
        model = load_checkpoint(checkpoint, make_env(), algorithm)
        model.learn(TOTAL - model.num_timesteps, reset_num_timesteps=False)
        assert same(_weights(model, tmp_path), expected), f"resumed from {checkpoint.name}"
    if algorithm is None:
        assert [entry["phase"] for entry in model.curriculum_state["history"]] == ["destination", "mqi"]


def test_the_latest_complete_checkpoint_of_a_folder_is_loaded(tmp_path):
    _ddpg(_short_pendulum()).learn(250, callback=ExactCheckpointCallback(100, str(tmp_path), name_prefix="ddpg"))
    assert checkpoint_files(tmp_path)[0].name == "ddpg_200_steps.zip"
    (tmp_path / "ddpg_training_state_200_steps.pkl").unlink()  # as a kill while saving leaves it (the zip comes last)
    assert checkpoint_files(tmp_path)[0].name == "ddpg_100_steps.zip"
    assert load_checkpoint(tmp_path, _short_pendulum(), DDPG).num_timesteps == 100
    with pytest.raises(FileNotFoundError, match=r"has no ddpg_training_state_200_steps\.pkl"):
        load_checkpoint(tmp_path / "ddpg_200_steps.zip", _short_pendulum(), DDPG)
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="empty holds no checkpoint of ExactCheckpointCallback"):
        checkpoint_files(tmp_path / "empty")
    with pytest.raises(FileNotFoundError, match=r"ddpg_replay_buffer_100_steps\.pkl is not a checkpoint"):
        checkpoint_files(tmp_path / "ddpg_replay_buffer_100_steps.pkl")


def test_a_checkpoint_resumed_on_an_env_built_otherwise_is_refused(tmp_path):
    _ddpg(_short_pendulum()).learn(120, callback=ExactCheckpointCallback(100, str(tmp_path)))
    other = gym.wrappers.RecordEpisodeStatistics(_short_pendulum())  # one wrapper more than the trained env had
    with pytest.raises(ValueError, match="wrappers, the env to resume"):
        load_checkpoint(tmp_path, other, DDPG)


@pytest.mark.parametrize("save_freq", [0, -5, 2.5, True])
def test_a_save_frequency_that_is_not_a_positive_count_is_refused(tmp_path, save_freq):
    with pytest.raises(ValueError, match=f"save_freq must be a positive number of calls, got {save_freq!r}"):
        ExactCheckpointCallback(save_freq, str(tmp_path))


@pytest.mark.parametrize("keep_last", [0, -1, 1.5, True])
def test_a_number_of_checkpoints_to_keep_that_is_not_a_positive_count_is_refused(tmp_path, keep_last):
    with pytest.raises(ValueError, match=f"keep_last must be a positive number of checkpoints or None, got {keep_last!r}"):
        ExactCheckpointCallback(100, str(tmp_path), keep_last=keep_last)


def test_keep_last_keeps_the_latest_checkpoints_of_its_prefix_only(tmp_path):
    env = gym.make("Pendulum-v1", max_episode_steps=50)
    other = tmp_path / "other_50_steps.zip"
    other.write_bytes(b"")  # another prefix's file in the folder: not this callback's to remove
    _ddpg(env).learn(300, callback=ExactCheckpointCallback(50, str(tmp_path), keep_last=2))
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        "other_50_steps.zip",
        *(
            f"rl_model_{part}{steps}_steps.{ext}"
            for part, ext in [("", "zip"), ("replay_buffer_", "pkl"), ("training_state_", "pkl")]
            for steps in (250, 300)
        ),
    ]


@pytest.mark.parametrize(
    ("make_env", "kind"),
    [
        (lambda: VecNormalize(DummyVecEnv([_short_pendulum])), "VecNormalize"),
        (lambda: DummyVecEnv([_short_pendulum] * 2), "DummyVecEnv of 2 envs"),
    ],
)
def test_a_model_on_another_vector_env_is_refused_with_the_callback_that_suits_it(tmp_path, make_env, kind):
    with pytest.raises(TypeError, match=rf"trains on a {kind} \(SB3's CheckpointCallback"):
        _ddpg(make_env()).learn(10, callback=ExactCheckpointCallback(5, str(tmp_path)))


def test_an_on_policy_model_is_refused_with_the_callback_that_suits_it(tmp_path):
    with pytest.raises(TypeError, match=r"saves an off-policy model's replay buffer; PPO has none \(SB3's CheckpointCallback"):
        PPO("MlpPolicy", _short_pendulum(), n_steps=16, batch_size=16).learn(
            10, callback=ExactCheckpointCallback(5, str(tmp_path))
        )
