"""`dhrl export` for every algorithm: the ONNX model passes onnx.checker and, run by
onnxruntime on the 1,000 recorded x_t, gives dhrl's own actions; the safetensors hold the
weights in PyTorch's layout (a numpy forward pass in nn.Linear's convention, and a plain torch
module where torch is installed, give the same actions); the Python DelayedPolicy replays the
Rust runtime's recorded decisions step for step."""

import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")
pytest.importorskip("safetensors")

from safetensors.numpy import load_file  # noqa: E402

from conftest import run_dhrl  # noqa: E402
from dhrl.deploy import DelayedPolicy, DelayedPolicyError, OnnxPolicy, read_manifest  # noqa: E402

TOLERANCE = 1e-5


def algorithms(binary: pathlib.Path) -> list:
    """The registry's algorithm names, as `dhrl train` lists them."""
    done = subprocess.run([str(binary), "train", "--algo", "?"], capture_output=True, text=True)
    listed = re.search(r"possible values: ([^\]]+)\]", done.stderr)
    assert listed, done.stderr
    return [name.strip() for name in listed.group(1).split(",")]


@pytest.fixture(scope="module")
def exports(dhrl_bin, tmp_path_factory) -> dict:
    """Each algorithm trained for a few hundred steps and exported: InvertedPendulum at Δ = 3
    or HalfCheetah under random delays up to 3 (SAC, delay-free, at Δ = 0)."""
    root = tmp_path_factory.mktemp("exports")
    out = {}
    for i, algo in enumerate(algorithms(dhrl_bin)):
        if algo == "sac":
            task, delay = "inverted-pendulum", []
        elif i % 2 == 0:
            task, delay = "half-cheetah", ["--random-delay", "--max-delay", "3"]
        else:
            task, delay = "inverted-pendulum", ["--delay", "3"]
        run = root / algo
        run_dhrl(
            dhrl_bin, "train", "--task", task, "--algo", algo, "--steps", "300", "--warmup-steps", "100",
            "--batch-size", "32", "--eval-every", "300", "--eval-episodes", "1", *delay, "--out", str(run),
        )
        run_dhrl(dhrl_bin, "export", str(run), "--out", str(root / f"{algo}-export"))
        out[algo] = root / f"{algo}-export"
    return out


def each_export(exports):
    return sorted(exports.items())


def test_every_onnx_model_passes_the_checker(exports):
    for algo, folder in each_export(exports):
        model = onnx.load(str(folder / "policy.onnx"))
        onnx.checker.check_model(model, full_check=True)
        assert model.opset_import[0].version == read_manifest(folder)["files"]["onnx_opset"], algo


def test_onnxruntime_gives_dhrls_actions_on_the_recorded_states(exports):
    for algo, folder in each_export(exports):
        manifest = read_manifest(folder)
        check = load_file(str(folder / "check.safetensors"))
        x = check["augmented_state"]
        assert x.shape == (1000, manifest["augmented_state"]["width"]), algo
        expected = check["action"][check["policy_step"] == 1]
        outputs = OnnxPolicy(folder).outputs(x)
        error = np.abs(outputs["action"] - expected).max()
        assert error <= TOLERANCE, f"{algo}: largest difference {error}"
        low, high = manifest["network"]["log_std_bounds"]
        assert np.all((outputs["log_std"] >= low) & (outputs["log_std"] <= high)), algo
        squashed = np.tanh(outputs["mean"]) * (np.subtract(manifest["action_high"], manifest["action_low"]) / 2)
        squashed += np.add(manifest["action_high"], manifest["action_low"]) / 2
        assert np.abs(squashed - outputs["action"]).max() <= TOLERANCE, algo


def replay(folder: pathlib.Path, policy: DelayedPolicy, tolerance: float, algo: str) -> None:
    """Feeds `policy` the recorded arrivals (in their order, out of order under random delays)
    and resets, comparing x_t and the action at each decision with the Rust runtime's."""
    check = load_file(str(folder / "check.safetensors"))
    recorded_x = iter(check["augmented_state"])
    arrivals = list(zip(check["arrival_decision"].astype(int), check["arrival_step"].astype(int),
                        check["arrival_observation"]))
    starts = 0
    for t in range(len(check["episode_start"])):
        if check["episode_start"][t]:
            policy.reset()
            starts += 1
        while arrivals and arrivals[0][0] == t:
            _, step, observation = arrivals.pop(0)
            policy.observe(step, observation)
        x = policy.augmented_state
        if check["policy_step"][t]:
            error = np.abs(x - next(recorded_x)).max()
            assert error <= tolerance, f"{algo}: x_t of decision {t} differs by {error}"
        else:
            assert x is None, f"{algo}: decision {t} is a warm-up"
        error = np.abs(policy.act() - check["action"][t]).max()
        assert error <= tolerance, f"{algo}: decision {t} differs by {error}"
    assert starts >= 2 and not arrivals, algo


def test_the_python_runtime_builds_the_rust_runtimes_x_t_exactly(exports):
    """With the recorded actions as its policy, every x_t and action is the Rust one, bit for bit."""
    for algo, folder in each_export(exports):
        check = load_file(str(folder / "check.safetensors"))
        recorded = iter(check["action"][check["policy_step"] == 1])
        replay(folder, DelayedPolicy(folder, warmup="zeros", policy=lambda x: next(recorded)), 0.0, algo)


def test_the_python_runtime_with_onnx_replays_the_rust_runtime(exports):
    """With the exported ONNX network, step for step within the tolerance (the actions it feeds
    back into x_t are onnxruntime's own)."""
    for algo, folder in each_export(exports):
        replay(folder, DelayedPolicy(folder, warmup="zeros"), TOLERANCE, algo)


def linear(state: dict, name: str, x: np.ndarray) -> np.ndarray:
    """nn.Linear's convention: weight [out, in], y = x·Wᵀ + b."""
    return x @ state[f"{name}.weight"].T + state[f"{name}.bias"]


def layer_norm(state: dict, name: str, x: np.ndarray) -> np.ndarray:
    mean = x.mean(-1, keepdims=True)
    var = ((x - mean) ** 2).mean(-1, keepdims=True)
    return (x - mean) / np.sqrt(var + 1e-5) * state[f"{name}.weight"] + state[f"{name}.bias"]


def numpy_forward(manifest: dict, state: dict, x: np.ndarray) -> np.ndarray:
    """The deterministic action from the safetensors alone, as docs/deploy.md lays them out."""
    x = x.astype(np.float64)
    state = {k: v.astype(np.float64) for k, v in state.items()}
    obs, act, delay = manifest["observation_dim"], manifest["action_dim"], manifest["delay"]["total"]
    kind = manifest["network"]["kind"]
    if kind == "gaussian-policy-on-last-observation":
        h = x[:, :obs]
    elif kind == "gaussian-policy-on-augmented-state":
        h = x
    elif kind == "forward-model-rollout-then-gaussian-policy":
        h = x[:, :obs]
        layers = sorted({int(k.split(".")[2]) for k in state if k.startswith("model.layers.")})
        for k in range(delay):
            z = np.concatenate([h, x[:, obs + k * act : obs + (k + 1) * act]], axis=1)
            if "model.input_mean" in state:
                z = (z - state["model.input_mean"]) / state["model.input_std"]
            for i in layers:
                z = linear(state, f"model.layers.{i}", z)
                if i != layers[-1]:
                    z = np.maximum(z, 0)
            h = h + z if manifest["network"]["model_predicts_difference"] else z
    else:
        assert kind == "belief-transformer-then-gaussian-policy", kind
        rows = x.shape[0]
        s, a = x[:, :obs], x[:, obs:].reshape(rows, delay, act)
        tokens = linear(state, "belief.token", np.concatenate(
            [np.repeat(linear(state, "belief.state_embedding", s)[:, None, :], delay, 1),
             linear(state, "belief.action_embedding", a)], axis=2))
        z = layer_norm(state, "belief.input_norm", tokens + state["belief.position.weight"])
        blocks = sorted({int(k.split(".")[2]) for k in state if k.startswith("belief.blocks.")})
        width = z.shape[-1]
        heads = manifest["network"]["attention_heads"]
        causal = np.triu(np.ones((delay, delay), dtype=bool), 1)
        for j in blocks:
            b = f"belief.blocks.{j}"
            n = layer_norm(state, f"{b}.attention_norm", z)
            split = lambda name: linear(state, f"{b}.{name}", n).reshape(rows, delay, heads, -1).transpose(0, 2, 1, 3)  # noqa: E731
            q, k_, v = split("query"), split("key"), split("value")
            scores = q @ k_.transpose(0, 1, 3, 2) / np.sqrt(width // heads)
            scores = np.where(causal, -1e4, scores)
            weights = np.exp(scores - scores.max(-1, keepdims=True))
            weights /= weights.sum(-1, keepdims=True)
            context = (weights @ v).transpose(0, 2, 1, 3).reshape(rows, delay, width)
            z = z + linear(state, f"{b}.attention_output", context)
            inner = linear(state, f"{b}.feed_forward_inner", layer_norm(state, f"{b}.feed_forward_norm", z))
            from math import erf

            gelu = inner * 0.5 * (1 + np.vectorize(erf)(inner / np.sqrt(2)))
            z = z + linear(state, f"{b}.feed_forward_outer", gelu)
        h = layer_norm(state, "belief.output_norm", z)[:, -1, :]
    hidden = sorted({int(k.split(".")[2]) for k in state if k.startswith("policy.hidden.")})
    for i in hidden:
        h = np.maximum(linear(state, f"policy.hidden.{i}", h), 0)
    low, high = np.asarray(manifest["action_low"]), np.asarray(manifest["action_high"])
    return np.tanh(linear(state, "policy.mean", h)) * (high - low) / 2 + (high + low) / 2


def test_the_safetensors_in_pytorchs_layout_give_the_same_actions(exports):
    for algo, folder in each_export(exports):
        manifest = read_manifest(folder)
        state = load_file(str(folder / "policy.safetensors"))
        shapes = {p["name"]: list(p["shape"]) for p in manifest["network"]["parameters"]}
        assert {k: list(v.shape) for k, v in state.items()} == shapes, algo
        check = load_file(str(folder / "check.safetensors"))
        x = check["augmented_state"][:200]
        expected = check["action"][check["policy_step"] == 1][:200]
        error = np.abs(numpy_forward(manifest, state, x) - expected).max()
        assert error <= TOLERANCE, f"{algo}: largest difference {error}"


def test_a_plain_torch_module_loads_the_policy_weights(exports):
    torch = pytest.importorskip(
        "torch", reason="torch is not installed (PyPI's Linux wheel brings CUDA, gigabytes; CI goes without)"
    )
    for algo, folder in each_export(exports):
        manifest = read_manifest(folder)
        kind = manifest["network"]["kind"]
        if not kind.startswith("gaussian-policy-on-"):
            continue
        from safetensors.torch import load_file as load_torch

        state = {k[len("policy."):]: v for k, v in load_torch(str(folder / "policy.safetensors")).items()}
        hidden = sorted({int(k.split(".")[1]) for k in state if k.startswith("hidden.")})

        class GaussianPolicy(torch.nn.Module):
            def __init__(self):
                super().__init__()
                self.hidden = torch.nn.ModuleList(
                    torch.nn.Linear(*reversed(state[f"hidden.{i}.weight"].shape)) for i in hidden
                )
                self.mean = torch.nn.Linear(*reversed(state["mean.weight"].shape))
                self.log_std = torch.nn.Linear(*reversed(state["log_std.weight"].shape))

            def forward(self, h):
                for layer in self.hidden:
                    h = torch.relu(layer(h))
                return torch.tanh(self.mean(h))

        module = GaussianPolicy()
        module.load_state_dict(state, strict=True)
        check = load_file(str(folder / "check.safetensors"))
        x = torch.from_numpy(check["augmented_state"])
        if kind == "gaussian-policy-on-last-observation":
            x = x[:, : manifest["observation_dim"]]
        low, high = np.asarray(manifest["action_low"]), np.asarray(manifest["action_high"])
        with torch.no_grad():
            actions = module(x).numpy() * (high - low) / 2 + (high + low) / 2
        expected = check["action"][check["policy_step"] == 1]
        assert np.abs(actions - expected).max() <= TOLERANCE, algo


def test_random_delays_arrive_out_of_order_in_the_record(exports):
    """Under random delays the recorded arrivals overtake each other (and the runtimes above
    replayed them): the conservative agent's waiting is exercised, not only the fixed delay."""
    for algo, folder in each_export(exports):
        if not read_manifest(folder)["delay"]["random"]:
            continue
        steps = load_file(str(folder / "check.safetensors"))["arrival_step"]
        assert np.any(np.diff(steps) < 0) and np.any(np.diff(steps) > 1), algo


def test_the_runtime_refuses_what_the_delay_model_rules_out(exports):
    folder = exports["bpql"]
    manifest = read_manifest(folder)
    obs, delay = manifest["observation_dim"], manifest["delay"]["total"]
    policy = DelayedPolicy(folder)
    for step in (-1, 1.5, True):
        with pytest.raises(DelayedPolicyError, match="accepted is a whole number ≥ 0"):
            policy.observe(step, np.zeros(obs))
    with pytest.raises(DelayedPolicyError, match=f"the policy takes {obs}"):
        policy.observe(0, np.zeros(obs + 1))
    with pytest.raises(DelayedPolicyError, match="non-finite value at index 2"):
        policy.observe(0, np.where(np.arange(obs) == 2, np.nan, 0.0))
    with pytest.raises(DelayedPolicyError, match="cannot have arrived before decision 0"):
        policy.observe(1, np.zeros(obs))
    for _ in range(delay):
        policy.act()
    with pytest.raises(DelayedPolicyError, match=f"needs the observation of step 0 \\(Δ = {delay}\\)"):
        policy.act()
    policy.observe(0, np.zeros(obs))
    with pytest.raises(DelayedPolicyError, match="arrived twice"):
        policy.observe(0, np.zeros(obs))
    assert policy.act().shape == (manifest["action_dim"],)
    late = DelayedPolicy(folder)
    for _ in range(delay):
        late.act()
    late.observe(0, np.zeros(obs))
    late.act()
    with pytest.raises(DelayedPolicyError, match="after it was needed"):
        late.observe(0, np.ones(obs))


REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
DEPLOY_RUN = REPOSITORY / "docs" / "runs" / "inverted-pendulum_bpql_delay3_30k-steps_deploy"
EXAMPLE = REPOSITORY / "examples" / "deploy_gymnasium.py"
RETURN = re.compile(r"return (-?[0-9.]+) ± ([0-9.]+) over (\d+) episodes")


def run_example(export: pathlib.Path, *args: str) -> str:
    done = subprocess.run([sys.executable, str(EXAMPLE), str(export), *args], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_gymnasium_example_balances_the_pendulum_as_dhrl_eval_does(dhrl_bin, tmp_path):
    """The checked-in BPQL run (InvertedPendulum, Δ = 3, 30k steps) exported and driven through
    Gymnasium's own InvertedPendulum-v4 inside DelayObservation by the Python runtime alone:
    its return is dhrl eval's."""
    export = tmp_path / "export"
    run_dhrl(dhrl_bin, "export", str(DEPLOY_RUN), "--out", str(export))
    out = run_example(export, "--episodes", "5", "--dhrl", str(dhrl_bin), "--run", str(DEPLOY_RUN))
    gymnasium_line, dhrl_line = out.strip().splitlines()
    assert "InvertedPendulum-v4 + DelayObservation(delay=3)" in gymnasium_line
    (gym_mean, gym_std, _), (dhrl_mean, _, _) = (RETURN.search(gymnasium_line).groups(), RETURN.search(dhrl_line).groups())
    assert float(dhrl_mean) == 1000.0, dhrl_line
    assert float(gym_mean) == float(dhrl_mean) and float(gym_std) == 0.0, out


def test_the_gymnasium_example_drives_halfcheetah(exports, dhrl_bin):
    """HalfCheetah-v4 too (a policy of a few hundred steps: it runs, and both returns print)."""
    algo = next(a for a, folder in sorted(exports.items()) if read_manifest(folder)["task"] == "half-cheetah")
    out = run_example(exports[algo], "--episodes", "1")
    assert "HalfCheetah-v4 + DelayObservation(delay=3)" in out and RETURN.search(out), out


def test_the_gymnasium_example_refuses_an_action_delay(dhrl_bin, tmp_path):
    run = tmp_path / "run"
    run_dhrl(dhrl_bin, "train", "--task", "inverted-pendulum", "--algo", "bpql", "--delay", "1", "--action-delay", "1",
             "--steps", "150", "--warmup-steps", "100", "--batch-size", "16", "--eval-every", "150",
             "--eval-episodes", "1", "--out", str(run))
    run_dhrl(dhrl_bin, "export", str(run), "--out", str(tmp_path / "export"))
    done = subprocess.run([sys.executable, str(EXAMPLE), str(tmp_path / "export")], capture_output=True, text=True)
    assert done.returncode != 0 and "action delay of 1" in done.stderr, done.stderr
