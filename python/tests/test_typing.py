"""The package's typing: ``dhrl/_dhrl.pyi`` describes the built extension exactly (names,
parameter names, getters vs methods, and the keys and dtypes of the dicts ``Batch`` returns),
and the ``py.typed`` marker and the stub ship with the package (maturin takes every file of
the package folder that git does not ignore)."""

import ast
import inspect
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

from dhrl import _dhrl

PACKAGE = pathlib.Path(_dhrl.__file__).resolve().parent
STUB = PACKAGE / "_dhrl.pyi"


@pytest.fixture(scope="module")
def stub() -> ast.Module:
    return ast.parse(STUB.read_text())


def top_level(stub: ast.Module) -> dict[str, ast.AST]:
    names: dict[str, ast.AST] = {}
    for node in stub.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            names[node.name] = node
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names[node.target.id] = node
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Name):
                    names[target.id] = node
    return names


def parameters(function: ast.FunctionDef) -> list[str]:
    return [a.arg for a in function.args.posonlyargs + function.args.args + function.args.kwonlyargs]


def runtime_parameters(obj) -> list[str]:
    return list(inspect.signature(obj).parameters)


def dtype_of(annotation: ast.expr) -> str:
    """``npt.NDArray[np.float32]`` → ``"float32"`` (``np.bool_`` → ``"bool"``)."""
    assert isinstance(annotation, ast.Subscript), ast.unparse(annotation)
    assert ast.unparse(annotation.value) == "npt.NDArray", ast.unparse(annotation)
    return np.dtype(getattr(np, ast.unparse(annotation.slice).removeprefix("np."))).name


def typed_dict(names: dict[str, ast.AST], name: str) -> dict[str, ast.expr]:
    """A stub TypedDict's fields, its bases' included."""
    node = names[name]
    assert isinstance(node, ast.ClassDef)
    fields: dict[str, ast.expr] = {}
    for base in node.bases:
        if ast.unparse(base) != "TypedDict":
            fields.update(typed_dict(names, ast.unparse(base)))
    for item in node.body:
        if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
            fields[item.target.id] = item.annotation
    return fields


def check_arrays(fields: dict[str, ast.expr], names: dict[str, ast.AST], value: dict, where: str) -> None:
    assert set(fields) == set(value), f"{where}: stub keys {sorted(fields)} vs runtime {sorted(value)}"
    for key, annotation in fields.items():
        if ast.unparse(annotation) == "bool":
            assert isinstance(value[key], bool), (where, key, type(value[key]))
        elif isinstance(annotation, ast.Name):  # a nested TypedDict
            check_arrays(typed_dict(names, annotation.id), names, value[key], f"{where}[{key!r}]")
        else:
            assert isinstance(value[key], np.ndarray), (where, key)
            assert dtype_of(annotation) == value[key].dtype.name, (where, key, value[key].dtype)


def test_module_names_match(stub):
    names = top_level(stub)
    public = {n for n in dir(_dhrl) if not n.startswith("_")}
    assert public == {"Batch", "raw_mj_step_rate", "TASKS", "MAX_DELAY", "set_assets_dir", "assets_dir"}
    assert public <= set(names), f"missing from the stub: {sorted(public - set(names))}"
    stub_public = {n for n in names if not n.startswith("_")}
    assert stub_public == public, f"in the stub only: {sorted(stub_public - public)}"
    declared = ast.literal_eval(names["__all__"].value)
    assert sorted(declared) == sorted(_dhrl.__all__)
    assert parameters(names["raw_mj_step_rate"]) == runtime_parameters(_dhrl.raw_mj_step_rate)
    assert isinstance(_dhrl.MAX_DELAY, int)
    assert isinstance(_dhrl.TASKS, list) and all(
        isinstance(t, tuple) and len(t) == 2 and all(isinstance(s, str) for s in t) for t in _dhrl.TASKS
    )
    assert ast.unparse(names["TASKS"].annotation) == "Final[list[tuple[str, str]]]"


def test_batch_members_match(stub):
    batch = top_level(stub)["Batch"]
    assert isinstance(batch, ast.ClassDef)
    members = {item.name: item for item in batch.body if isinstance(item, ast.FunctionDef)}
    properties = {n for n, f in members.items() if any(ast.unparse(d) == "property" for d in f.decorator_list)}
    runtime = {n: v for n, v in vars(_dhrl.Batch).items() if not n.startswith("_")}
    getters = {n for n, v in runtime.items() if inspect.isgetsetdescriptor(v)}
    methods = {n for n, v in runtime.items() if inspect.ismethoddescriptor(v) and not inspect.isgetsetdescriptor(v)}
    assert getters | methods == set(runtime)
    assert properties == getters
    assert set(members) - {"__new__"} - properties == methods
    # The constructor (pyo3's #[new]) and every method take the stub's parameters, by name.
    assert parameters(members["__new__"])[1:] == runtime_parameters(_dhrl.Batch)
    for name in methods:
        assert parameters(members[name]) == runtime_parameters(runtime[name]), name
    # Parameters with defaults: the same ones.
    step = members["step"]
    assert [ast.unparse(d) for d in step.args.defaults] == ["None"]
    assert str(inspect.signature(_dhrl.Batch.step).parameters["controls"].default) == "None"


ARGS = ("hopper", 2, 2, 0, None, 0.0, "zeros", 0, 1)


def test_returned_dicts_and_values_match_the_stub(stub):
    names = top_level(stub)
    batch = _dhrl.Batch(*ARGS)
    check_arrays(typed_dict(names, "_Current"), names, batch.current(), "current()")
    check_arrays(typed_dict(names, "_Current"), names, batch.set_state([0.0] * 6, [0.0] * 6), "set_state()")
    check_arrays(typed_dict(names, "_Current"), names, batch.reseed(3), "reseed()")
    # Steps until transitions complete (Δ = 2), so that their rows are real ones.
    for _ in range(5):
        out = batch.step(np.zeros((2, 3), np.float32), np.zeros(2, np.uint8))
    assert len(out["transitions"]["env"]) == 2
    check_arrays(typed_dict(names, "_Stepped"), names, out, "step()")
    # `done` and `ended` say what the flags say, up to and through a step that ends an episode.
    for _ in range(1000):
        np.testing.assert_array_equal(out["done"], out["terminated"] | out["truncated"])
        assert out["ended"] == bool(out["done"].any())
        if out["ended"]:
            break
        out = batch.step(np.ones((2, 3), np.float32), np.zeros(2, np.uint8))
    assert out["ended"], "no episode ended in 1,000 steps"
    low, high = batch.action_bounds()
    assert low.dtype == high.dtype == np.float64
    assert isinstance(batch.workers_flush_subnormals(), list)
    assert isinstance(batch.time_native_steps(np.zeros((1, 2, 3), np.float32), 2), float)
    assert isinstance(_dhrl.raw_mj_step_rate("hopper", 1, 10), float)
    assert isinstance(_dhrl.raw_mj_step_rate("hopper", 4, 40, threads=2), float)
    for getter in ("task", "gymnasium_id"):
        assert isinstance(getattr(batch, getter), str)
    for getter in ("num_envs", "obs_dim", "act_dim", "delay", "augmented_dim", "num_threads"):
        assert isinstance(getattr(batch, getter), int)


def test_typing_files_ship_with_the_package():
    assert (PACKAGE / "py.typed").is_file()
    assert STUB.is_file()
    git = shutil.which("git")
    if git is None or subprocess.run([git, "rev-parse"], cwd=PACKAGE, capture_output=True).returncode != 0:
        pytest.skip("not in a git work tree: maturin's file selection (git-ignored files left out) cannot be checked")
    ignored = subprocess.run(
        [git, "check-ignore", "--no-index", "py.typed", "_dhrl.pyi"], cwd=PACKAGE, capture_output=True, text=True
    )
    assert ignored.stdout == "", f"git-ignored, so maturin would leave them out: {ignored.stdout}"
