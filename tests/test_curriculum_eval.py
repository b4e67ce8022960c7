"""Evaluation during training follows the curriculum's reward phase (tests/phased_env.py)."""

import numpy as np
import pytest
from phased_env import PhasedPointEnv
from stable_baselines3 import DDPG
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback
from stable_baselines3.common.env_util import make_vec_env

from sb3_dtdpg import DTDPG, CurriculumTransferCallback, Phase

# Every episode lasts 20 steps (the robot cannot arrive), so the 3-episode first phase ends at step 60.
LONG_EPISODES = {"starts": [[0.1, 0.1]], "destinations": [[0.9, 0.9]], "v_max": 0.03}
PHASES = [Phase("destination", n_episodes=3, sigma=0.5), Phase("mqi", sigma=0.3)]
TRANSFER_STEP = 60


def make_env(**kwargs):
    return make_vec_env(PhasedPointEnv, n_envs=1, seed=0, env_kwargs={**LONG_EPISODES, **kwargs})


class RecordPhase(BaseCallback):
    """After each evaluation: the step and the reward phase the parent EvalCallback's env evaluated on."""

    def __init__(self):
        super().__init__()
        self.phases = []

    def _on_step(self) -> bool:
        self.phases.append((self.num_timesteps, self.parent.eval_env.get_attr("reward_phase")[0]))
        return True


class TrialEval(EvalCallback):
    """Stands for the RL Zoo's TrialEvalCallback: an Optuna objective (it has a ``trial``)."""

    trial = object()


def evaluation(tmp_path, name, **env_kwargs):
    recorder = RecordPhase()
    callback = EvalCallback(
        make_env(**env_kwargs), eval_freq=20, n_eval_episodes=1, log_path=str(tmp_path / name), callback_after_eval=recorder
    )
    return callback, recorder


@pytest.mark.parametrize("algo", ["dtdpg", "ddpg"])
def test_eval_env_follows_the_reward_phase_and_best_model_is_picked_on_the_last_one(algo, tmp_path):
    kwargs = {"learning_starts": 10, "batch_size": 16, "policy_kwargs": {"net_arch": [16]}, "seed": 0}
    evaluation_callback, recorder = evaluation(tmp_path, "eval")
    trial_recorder = RecordPhase()
    trial = TrialEval(make_env(reward_phase="mqi"), eval_freq=20, n_eval_episodes=1, callback_after_eval=trial_recorder)
    if algo == "dtdpg":
        model = DTDPG("MlpPolicy", make_env(), phases=PHASES, **kwargs)
        model.learn(120, callback=[evaluation_callback, trial])
    else:
        model = DDPG("MlpPolicy", make_env(), **kwargs)
        curriculum = CurriculumTransferCallback(PHASES, eval_callbacks=[evaluation_callback])
        model.learn(120, callback=[curriculum, evaluation_callback])

    # The transfer comes before the evaluation of the same step
    expected = [(t, "destination" if t < TRANSFER_STEP else "mqi") for t in range(20, 121, 20)]
    assert recorder.phases == expected
    history = model.curriculum_state["history"]
    assert [(entry["phase"], entry["reward_phase"]) for entry in history] == [("destination", "destination"), ("mqi", "mqi")]
    assert history[1]["start_timestep"] == TRANSFER_STEP
    # best_mean_reward was reset at the transfer: the best over the evaluations on the mqi reward only
    after = [
        np.mean(r)
        for t, r in zip(evaluation_callback.evaluations_timesteps, evaluation_callback.evaluations_results, strict=True)
        if t >= TRANSFER_STEP
    ]
    assert evaluation_callback.best_mean_reward == pytest.approx(max(after))
    if algo == "dtdpg":
        # A search objective keeps its env's reward, for every trial alike
        assert trial_recorder.phases == [(t, "mqi") for t in range(20, 121, 20)]


def test_an_eval_env_without_reward_phases_is_an_error(tmp_path):
    from stable_baselines3.common.env_util import make_vec_env as make

    pendulum = EvalCallback(make("Pendulum-v1", n_envs=1), eval_freq=20, n_eval_episodes=1)
    model = DTDPG("MlpPolicy", make_env(), phases=PHASES, learning_starts=10, policy_kwargs={"net_arch": [16]})
    with pytest.raises(ValueError, match="eval env of EvalCallback has no set_reward_phase"):
        model.learn(40, callback=pendulum)


def test_an_evaluation_inside_another_callback_follows_the_reward_phase(tmp_path):
    # EveryNTimesteps (an EventCallback) around an EvalCallback, and one as another's callback_on_new_best: both
    # evaluated the destination reward after the transfer
    from stable_baselines3.common.callbacks import EveryNTimesteps

    kwargs = {"learning_starts": 10, "batch_size": 16, "policy_kwargs": {"net_arch": [16]}, "seed": 0}
    inner, recorder = evaluation(tmp_path, "inner")
    inner.eval_freq = 1
    on_best = EvalCallback(make_env(), eval_freq=1, n_eval_episodes=1)
    outer = EvalCallback(make_env(), eval_freq=20, n_eval_episodes=1, callback_on_new_best=on_best)
    model = DTDPG("MlpPolicy", make_env(), phases=PHASES, **kwargs)
    model.learn(120, callback=[EveryNTimesteps(20, inner), outer])
    assert recorder.phases == [(t, "destination" if t < TRANSFER_STEP else "mqi") for t in range(20, 121, 20)]
    assert on_best.eval_env.get_attr("reward_phase") == ["mqi"]


@pytest.mark.parametrize("nested", [False, True])
def test_dtdpg_refuses_a_curriculum_callback_of_its_own(nested):
    # DTDPG adds its own: a second one counted every step twice (phase 0 ended at half its budget)
    from stable_baselines3.common.callbacks import CallbackList

    model = DTDPG("MlpPolicy", make_env(), phases=PHASES, learning_starts=10, batch_size=16, seed=0)
    extra = CurriculumTransferCallback(PHASES)
    with pytest.raises(ValueError, match=r"callback: DTDPG runs its own CurriculumTransferCallback"):
        model.learn(40, callback=CallbackList([extra]) if nested else extra)
    assert model.num_timesteps == 0
