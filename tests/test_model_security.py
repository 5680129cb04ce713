"""Model loading cannot run code from the model's files by default (issue 14, defect 1;
docs/security.md).

Each payload is a pickle whose unpickling creates a marker file (``open(marker, "w")``).
The tests check that the marker does NOT appear when loading by default, and that it
DOES appear through the trusted path: so the payload is live and the test could fail.
"""

from __future__ import annotations

import base64
import json
import pickle
import shutil
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from policies import PRETRAINED_DIR, load_policy
from policies.sb3 import (
    MANIFEST_NAME,
    UntrustedModelError,
    check_manifest,
    safe_custom_objects,
    write_manifest,
)

pytestmark = pytest.mark.skipif(
    not (PRETRAINED_DIR / "ppo.zip").is_file(), reason="no pretrained models"
)


class _Payload:
    """Unpickling it calls ``open(marker, "w")``: creates the marker file."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _payload_b64(marker: Path) -> str:
    return base64.b64encode(pickle.dumps(_Payload(marker))).decode()


def _copy_model(dst: Path, name: str = "ppo", stats: bool = True) -> Path:
    """``<name>.zip`` (and its npz + JSON statistics) copied to ``dst``, no manifest."""
    dst.mkdir(parents=True, exist_ok=True)
    shutil.copy(PRETRAINED_DIR / f"{name}.zip", dst)
    if stats:
        for suffix in (".npz", ".json"):
            shutil.copy(PRETRAINED_DIR / f"{name}_vecnormalize{suffix}", dst)
    return dst / f"{name}.zip"


def _poison_zip(model: Path, marker: Path, keys: tuple[str, ...]) -> None:
    """Rewrite the zip's ``data`` so that each of ``keys`` holds the payload as a
    ``:serialized:`` cloudpickle entry (a new key if it is not there)."""
    with zipfile.ZipFile(model) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    data = json.loads(entries["data"])
    for k in keys:
        item = data.get(k) if isinstance(data.get(k), dict) else {}
        data[k] = {**item, ":serialized:": _payload_b64(marker)}
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(model, "w") as z:
        for n, b in entries.items():
            z.writestr(n, b)


def _obs(n: int | None = None) -> np.ndarray:
    """A plausible observation for the pretrained ppo model (trace empty, route ahead)."""
    if n is None:
        n = load_policy(PRETRAINED_DIR / "ppo.zip").model.observation_space.shape[0]
    obs = np.zeros(n, dtype=np.float32)
    obs[32:64] = np.column_stack([2.0 * np.arange(1, 17), np.zeros(16)]).ravel()
    return obs


@pytest.mark.parametrize("keys", [("policy_class",), ("lr_schedule", "clip_range"),
                                  ("observation_space", "_last_obs")])  # fmt: skip
def test_payload_in_a_known_zip_entry_is_not_run(tmp_path: Path, keys) -> None:
    """A payload in the entries SB3 would cloudpickle.loads is replaced through
    custom_objects: the model loads and acts, and the marker never appears."""
    marker = tmp_path / "pwned"
    model = _copy_model(tmp_path / "m")
    _poison_zip(model, marker, keys)
    pol = load_policy(model)
    assert pol.act(_obs()).shape == (2,)
    assert not marker.exists(), "the payload ran on a default load"
    # the payload is live: SB3's own (trusted) load runs it
    from stable_baselines3 import PPO

    try:
        PPO.load(str(model), device="cpu")
    except Exception:  # the replaced entry is a file object, not a class
        pass
    assert marker.exists(), "the payload should run through SB3's pickle path"


def test_payload_in_an_unknown_zip_entry_is_refused(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"
    model = _copy_model(tmp_path / "m")
    _poison_zip(model, marker, ("evil",))
    with pytest.raises(UntrustedModelError, match="evil"):
        load_policy(model)
    assert not marker.exists()
    load_policy(model, trust=True)  # the trusted path unpickles it
    assert marker.exists()


def test_unlisted_policy_class_is_refused(tmp_path: Path) -> None:
    model = _copy_model(tmp_path / "m")
    with zipfile.ZipFile(model) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    data = json.loads(entries["data"])
    data["policy_class"]["__module__"] = "evil.module"
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(model, "w") as z:
        for n, b in entries.items():
            z.writestr(n, b)
    with pytest.raises(UntrustedModelError, match="policy_class"):
        safe_custom_objects(model, "ppo")


def test_vecnormalize_pickle_needs_trust(tmp_path: Path) -> None:
    """A ``_vecnormalize.pkl`` (no npz + JSON beside it) is refused without trust, by
    load_policy and by cnt-evaluate (exit code 2, before any episode); --trust
    unpickles it."""
    marker = tmp_path / "pwned"
    model = _copy_model(tmp_path / "m", stats=False)
    (tmp_path / "m" / "ppo_vecnormalize.pkl").write_bytes(pickle.dumps(_Payload(marker)))
    with pytest.raises(UntrustedModelError, match="pickle"):
        load_policy(model)
    assert not marker.exists()

    from training.evaluate import main

    out = tmp_path / "eval"
    code = main(["--policies", "ppo", "--models", str(model.parent), "--targets", "u_turn",
                 "--seeds", "0", "--jobs", "1", "--out", str(out)])  # fmt: skip
    assert code == 2
    assert not marker.exists()
    assert not (out / "episodes.csv").exists()

    load_policy(model, trust=True)  # (its "statistics" are the payload's file object)
    assert marker.exists(), "trust=True reads the pickle"


def test_the_pretrained_models_pass_their_manifest_and_act() -> None:
    listed = json.loads((PRETRAINED_DIR / MANIFEST_NAME).read_text())["sha256"]
    assert not any(n.endswith(".pkl") for n in listed)
    assert not list(PRETRAINED_DIR.glob("*.pkl"))
    for name in ("ppo", "sac", "ppo_residual"):
        assert check_manifest(PRETRAINED_DIR / f"{name}.zip") is True
        # (the residual agent warns without env=: its base then reads only the obs)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            a = load_policy(PRETRAINED_DIR / f"{name}.zip").act(_obs())
        assert a.shape == (2,) and np.all(np.abs(a) <= 1.0)


def test_safe_load_acts_as_the_trusted_load() -> None:
    rng = np.random.default_rng(0)
    for name in ("ppo", "sac"):
        safe = load_policy(PRETRAINED_DIR / f"{name}.zip")
        trusted = load_policy(PRETRAINED_DIR / f"{name}.zip", trust=True)
        n_obs = safe.model.observation_space.shape[0]
        for _ in range(5):
            o = (3.0 * rng.normal(size=n_obs)).astype(np.float32)
            assert np.array_equal(safe.act(o), trusted.act(o))


@pytest.mark.parametrize("tamper", ["ppo.yml", "ppo_vecnormalize.npz", "ppo.zip", "extra"])
def test_a_tampered_file_fails_the_manifest(tmp_path: Path, tamper: str) -> None:
    d = tmp_path / "pretrained"
    shutil.copytree(PRETRAINED_DIR, d)
    model = d / "ppo.zip"
    assert check_manifest(model) is True
    if tamper == "extra":  # a file of the model the manifest does not list
        shutil.copy(d / "ppo_vecnormalize.json", d / "ppo_vecnormalize.pkl")
        match = "ppo_vecnormalize.pkl is not listed"
    else:
        with (d / tamper).open("ab") as fh:
            fh.write(b"\n")
        match = f"{tamper} does not match"
    with pytest.raises(UntrustedModelError, match=match):
        load_policy(model)
    with pytest.raises(UntrustedModelError, match=match):
        check_manifest(model)
    # the other models of the folder are untouched and still load
    load_policy(d / "sac.zip")
    if tamper != "ppo.zip":  # a zip with a trailing byte is still a zip: trust loads it
        with pytest.warns(UserWarning, match="manifest"):
            load_policy(model, trust=True)
    # after a trusted re-sign, it loads by default again
    write_manifest(d)
    if tamper != "extra":
        load_policy(model)


def test_a_missing_listed_file_fails_the_manifest(tmp_path: Path) -> None:
    d = tmp_path / "pretrained"
    shutil.copytree(PRETRAINED_DIR, d)
    (d / "ppo_vecnormalize.npz").unlink()
    with pytest.raises(UntrustedModelError, match="listed but missing"):
        load_policy(d / "ppo.zip")


def test_a_dict_space_is_rebuilt_from_its_text_and_anything_else_refused() -> None:
    """A Dict observation (obs_mode "dict") is rebuilt from the text SB3 writes beside its
    pickle: Boxes only, every one of them read, bounds of one value or an array."""
    from gymnasium import spaces

    from policies.sb3 import _space

    want = spaces.Dict({
        "image": spaces.Box(0, 255, (3, 8, 8), np.uint8),
        "vector": spaces.Box(np.array([-1.0, -1000.0], np.float32),
                             np.array([1.0, 5.0], np.float32)),
    })  # fmt: skip
    item = {":type:": "<class 'gymnasium.spaces.dict.Dict'>", ":serialized:": "x",
            "spaces": str(want.spaces)}  # fmt: skip
    assert _space(item) == want
    for bad in ("{'image': Discrete(3)}",
                str(want.spaces).replace("'vector': Box", "'vector': MultiBinary(2), 'v': Box"),
                "{'image': Box(0, 255, (3, 8, 8), object)}", ""):  # fmt: skip
        with pytest.raises(UntrustedModelError):
            _space({**item, "spaces": bad})
