"""RAFT loading: torchvision and original princeton-vl weights, lookup order, input handling."""

from __future__ import annotations

import re
import urllib.error
from pathlib import Path

import pytest
import torch
from torchvision.models.optical_flow import raft_large, raft_small

from lit_boot.data import read_flo, read_png
from lit_boot.flow import (
    checkpoint_dirs,
    convert_original_state_dict,
    load_raft,
    predict_flow,
    prepare_pair,
    resolve_weights,
)
from lit_boot.metrics import flow_errors


def _original_names(tv_state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """torchvision RAFT names -> the original repository's names (written independently of the
    forward conversion: REFERENCE section 4 and the original module attribute names)."""
    out = {}
    for key, value in tv_state.items():
        k = key.replace("feature_encoder.", "fnet.").replace("context_encoder.", "cnet.")
        k = re.sub(r"^(fnet|cnet)\.convnormrelu\.0\.", r"\1.conv1.", k)
        k = re.sub(r"^(fnet|cnet)\.convnormrelu\.1\.", r"\1.norm1.", k)
        k = re.sub(r"^(fnet|cnet)\.conv\.", r"\1.conv2.", k)
        k = re.sub(r"convnormrelu(\d)\.0\.", r"conv\1.", k)
        k = re.sub(r"convnormrelu(\d)\.1\.", r"norm\1.", k)
        k = k.replace("update_block.motion_encoder.", "update_block.encoder.")
        k = re.sub(r"encoder\.convcorr(\d)\.0\.", r"encoder.convc\1.", k)
        k = re.sub(r"encoder\.convflow(\d)\.0\.", r"encoder.convf\1.", k)
        k = k.replace("encoder.conv.0.", "encoder.conv.")
        k = k.replace("mask_predictor.convrelu.0.", "update_block.mask.0.").replace("mask_predictor.conv.", "update_block.mask.2.")
        out["module." + k] = value
    large = any(k.startswith("mask_predictor") for k in tv_state)
    renamed = {}
    for k, v in out.items():
        m = re.match(r"(.*)recurrent_block\.convgru(\d)\.conv([zrq])\.(.*)", k)
        if m:
            k = f"{m[1]}gru.conv{m[3]}{m[2] if large else ''}.{m[4]}"
        renamed[k] = v
        # The original residual block keeps its downsample norm under a second name too.
        m = re.match(r"(.*layer\d\.\d)\.downsample\.1\.(.*)", k)
        if m:
            renamed[f"{m[1]}.norm{3 if large else 4}.{m[2]}"] = v
    return renamed


@pytest.mark.parametrize("builder", [raft_small, raft_large])
def test_original_checkpoints_convert_by_name(builder):
    torch.manual_seed(0)
    model = builder()
    for p in model.state_dict().values():  # distinct values everywhere, BatchNorm stats included
        if p.is_floating_point():
            p.copy_(torch.randn_like(p))
    tv = model.state_dict()
    original = _original_names(tv)
    assert any(k.startswith("module.fnet.") for k in original)
    shuffled = dict(reversed(list(original.items())))  # order must not matter
    converted = convert_original_state_dict(shuffled)
    assert set(converted) == set(tv)
    for key in tv:
        assert torch.equal(converted[key], tv[key]), key


@pytest.mark.shared
def test_raft_small_original_weights_reproduce_sintel_epe(shared):
    """All-pixel EPE, 32 updates, original raft-small.pth converted by name."""
    model = load_raft("raft_small", shared / "checkpoints" / "raft-small.pth").eval()
    root = shared / "data" / "sintel_samples" / "training"
    for scene, frame, expected in [("alley_1", 2, 0.27), ("bandage_1", 35, 0.38)]:
        a = read_png(root / "final" / scene / f"frame_{frame:04d}.png")
        b = read_png(root / "final" / scene / f"frame_{frame + 1:04d}.png")
        gt = read_flo(root / "flow" / scene / f"frame_{frame:04d}.flo")
        with torch.no_grad():
            flow = predict_flow(model, a, b, num_flow_updates=32)[0]
        assert flow.shape == gt.shape
        assert flow_errors(flow, gt)["epe"].item() == pytest.approx(expected, abs=0.05), scene


@pytest.mark.shared
def test_lookup_order_and_offline_error(shared, tmp_path, monkeypatch):
    local = tmp_path / "ckpts"
    local.mkdir()
    monkeypatch.setenv("LIT_BOOT_CHECKPOINTS", str(local))
    monkeypatch.chdir(tmp_path)

    def offline(*args, **kwargs):
        raise urllib.error.URLError("no network")

    monkeypatch.setattr("torch.hub.load_state_dict_from_url", offline)
    with pytest.raises(FileNotFoundError) as err:
        resolve_weights("raft_small", "C_T_V1")
    message = str(err.value)
    assert "raft_small_C_T_V1-ad48884c.pth" in message and "raft-small.pth" in message and str(local) in message
    # The original file name placed in the checkpoint folder is found (a link, never a copy).
    (local / "raft-small.pth").symlink_to(shared / "checkpoints" / "raft-small.pth")
    assert resolve_weights("raft_small", "C_T_V1") == local / "raft-small.pth"
    # An explicit path wins over the lookup.
    assert resolve_weights("raft_small", shared / "checkpoints" / "raft-small.pth").parent == shared / "checkpoints"


@pytest.mark.real_checkpoint_dirs
def test_default_lookup_folders(shared, tmp_path, monkeypatch):
    # Without $LIT_BOOT_CHECKPOINTS: ./checkpoints of the working directory, then the project's.
    monkeypatch.delenv("LIT_BOOT_CHECKPOINTS", raising=False)
    monkeypatch.chdir(tmp_path)
    project = tmp_path / "project_checkpoints"
    project.mkdir()
    monkeypatch.setattr("lit_boot.flow.weights._PROJECT_CHECKPOINTS", project)
    assert checkpoint_dirs() == [tmp_path / "checkpoints", project]
    (project / "raft-small.pth").symlink_to(shared / "checkpoints" / "raft-small.pth")
    assert resolve_weights("raft_small", "C_T_V1") == project / "raft-small.pth"
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "raft-small.pth").symlink_to(shared / "checkpoints" / "raft-small.pth")
    assert resolve_weights("raft_small", "C_T_V1") == tmp_path / "checkpoints" / "raft-small.pth"


def test_bad_weights_give_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.pth"):
        load_raft("raft_small", tmp_path / "missing.pth")
    with pytest.raises(ValueError, match="C_T_V1"):
        load_raft("raft_small", "C_T_V9")
    foreign = tmp_path / "foreign.pth"
    torch.save({"encoder.weight": torch.zeros(2)}, foreign)
    with pytest.raises(ValueError, match="neither a torchvision RAFT state dict"):
        load_raft("raft_small", foreign)
    large = tmp_path / "large.pth"
    torch.save(raft_large().state_dict(), large)
    with pytest.raises(ValueError, match="holds raft_large weights"):
        load_raft("raft_small", large)
    garbage = tmp_path / "garbage.pth"
    garbage.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="garbage.pth"):
        load_raft("raft_small", garbage)
    with pytest.raises(ValueError, match="arch"):
        load_raft("raft_tiny", None)


def test_torchvision_format_file_round_trips(tmp_path):
    model = raft_small()
    path = tmp_path / "tv.pth"
    torch.save(model.state_dict(), path)
    loaded = load_raft("raft_small", path)
    for (k, a), b in zip(model.state_dict().items(), loaded.state_dict().values()):
        assert torch.equal(a, b), k


def test_inputs_any_size_and_dtype():
    torch.manual_seed(0)
    a = torch.randint(0, 256, (3, 13, 21), dtype=torch.uint8)
    b = torch.randint(0, 256, (3, 13, 21), dtype=torch.uint8)
    x, y, pad = prepare_pair(a, b)
    assert x.shape == (1, 3, 128, 128) and x.min() >= -1 and x.max() <= 1  # RAFT's smallest input
    left, right, top, bottom = pad
    assert torch.equal(x[..., top, :], x[..., 0, :])  # replicate padding
    torch.testing.assert_close(x[0, :, top : top + 13, left : left + 21], a.float() / 127.5 - 1)
    model = raft_small().eval()
    with torch.no_grad():
        f_uint8 = predict_flow(model, a, b, num_flow_updates=2)
        f_float = predict_flow(model, a.float() / 255, b.float() / 255, num_flow_updates=2)
    assert f_uint8.shape == (1, 2, 13, 21)
    torch.testing.assert_close(f_uint8, f_float)
    with pytest.raises(ValueError, match="image1"):
        prepare_pair(torch.zeros(1, 13, 21), b)


def test_known_sha256_table_agrees_with_readme_and_torchvision():
    from torchvision.models.optical_flow import Raft_Large_Weights, Raft_Small_Weights

    from lit_boot.flow.weights import KNOWN_SHA256

    readme = (Path(__file__).resolve().parents[1] / "checkpoints" / "README.md").read_text()
    torchvision = {Path(m.url).name for enum in (Raft_Small_Weights, Raft_Large_Weights) for m in enum}
    assert set(re.findall(r"`(raft_(?:small|large)_\w+-[0-9a-f]{8}\.pth)`", readme)) == torchvision
    assert {name: digits for name, digits in KNOWN_SHA256.items() if len(digits) == 8} == {
        name: re.search(r"-([0-9a-f]{8})\.pth$", name).group(1) for name in torchvision
    }
    whole = dict(re.findall(r"^\| `([^`]+)` \| `([0-9a-f]{64})` \|$", readme, flags=re.M))
    assert whole == {name: sha for name, sha in KNOWN_SHA256.items() if len(sha) == 64} and whole


@pytest.mark.shared
def test_known_weights_are_hash_checked_once(shared, tmp_path, monkeypatch):
    import hashlib

    from lit_boot.flow import weights

    calls = []
    real = hashlib.sha256
    monkeypatch.setattr(hashlib, "sha256", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setattr(weights, "_HASHES", {})
    original = shared / "checkpoints" / "raft-small.pth"
    load_raft("raft_small", original)
    load_raft("raft_small", original)
    assert len(calls) == 1  # hashed once per file per process
    other = tmp_path / "other.pth"
    torch.save(raft_small().state_dict(), other)
    load_raft("raft_small", other)  # an unknown name is not checked
    assert len(calls) == 1
    found = weights.file_sha256(other)
    known = [("raft-small.pth", "is c7d41b9cc884"), ("raft_small_C_T_V1-ad48884c.pth", "starts with ad48884c")]
    for name, expected in known:
        (tmp_path / name).symlink_to(other)  # a known name, other bytes
        message = rf"{name}: sha256 {found}, but the sha256 of {name} {expected}"
        with pytest.raises(weights.WeightsHashError, match=message):
            load_raft("raft_small", tmp_path / name)
    copy = tmp_path / "copy" / "raft-small.pth"
    copy.parent.mkdir()
    copy.write_bytes(original.read_bytes())
    load_raft("raft_small", copy)  # a faithful copy passes
    copy.write_bytes(original.read_bytes()[:-1000] + bytes(1000))  # changed in place: hashed again
    with pytest.raises(weights.WeightsHashError, match="copy/raft-small.pth"):
        load_raft("raft_small", copy)


@pytest.mark.parametrize("builder", [raft_small, raft_large])
def test_truncated_backprop_gives_the_forwards_flows_and_gradients_through_the_last_updates(builder):
    torch.manual_seed(0)
    model = builder().eval()  # random weights; eval: BatchNorm (raft_large's context) uses its running stats
    a, b = torch.rand(3, 40, 60), torch.rand(3, 40, 60)
    with torch.no_grad():
        full = predict_flow(model, a, b, num_flow_updates=5, all_updates=True)
        every = predict_flow(model, a, b, num_flow_updates=5, all_updates=True, grad_updates=5)
        last = predict_flow(model, a, b, num_flow_updates=5, all_updates=True, grad_updates=2)
    assert len(every) == 5 and len(last) == 2
    for mine, theirs in zip(every, full):  # the same iterations as torchvision's forward
        torch.testing.assert_close(mine, theirs, rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(last[-1], full[-1], rtol=1e-4, atol=1e-5)
    loss = predict_flow(model, a, b, num_flow_updates=5, grad_updates=2).abs().mean()
    loss.backward()
    grads = {name: p.grad for name, p in model.named_parameters()}
    assert grads["update_block.motion_encoder.convcorr1.0.weight"].abs().sum() > 0  # the last updates train
    assert grads["context_encoder.convnormrelu.0.weight"].abs().sum() > 0  # the context reaches them
    with pytest.raises(ValueError, match="grad_updates: expected 1..5"):
        predict_flow(model, a, b, num_flow_updates=5, grad_updates=6)
