"""A compile cache holds code (Inductor's generated code, pickled graphs), so it loads only where this user's torchgrade
signed it: every byte is checked against this user's key before PyTorch sees one, and a file from anywhere else is
refused with nothing loaded and nothing written."""

import contextlib
import os
import pickle
import stat
import subprocess
import sys

import pytest
import torch

import torchgrade as tg
from torchgrade.io.compile_cache import MAGIC, signed, verified
from torchgrade.io.user_key import KEY_BYTES, KEY_NAME, user_key


@pytest.fixture(autouse=True)
def key_folder(tmp_path, monkeypatch):
    """This user's key folder, in the test's own folder."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    return tmp_path / "config" / "torchgrade"


@pytest.fixture
def handed(monkeypatch) -> list:
    """What PyTorch's loader is handed (it takes everything); its saver gives known bytes."""
    given = []
    monkeypatch.setattr(torch.compiler, "save_cache_artifacts", lambda: (b"artifacts of a compile", None))
    monkeypatch.setattr(torch.compiler, "load_cache_artifacts", lambda data: given.append(data) or object())
    return given


def mode(path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def test_a_saved_cache_loads_and_pytorch_gets_its_bytes_as_they_were_saved(tmp_path, key_folder, handed):
    path = tmp_path / "look.compiled"
    assert tg.io.save_compile_cache(path)
    assert mode(key_folder) == 0o700 and mode(key_folder / KEY_NAME) == 0o600
    assert (key_folder / KEY_NAME).stat().st_size == KEY_BYTES and os.listdir(key_folder) == [KEY_NAME]
    assert tg.io.load_compile_cache(path) is True
    assert handed == [b"artifacts of a compile"]


def test_the_key_is_made_once(tmp_path, key_folder, handed):
    tg.io.save_compile_cache(tmp_path / "a.compiled")
    key = (key_folder / KEY_NAME).read_bytes()
    tg.io.save_compile_cache(tmp_path / "b.compiled")
    assert (key_folder / KEY_NAME).read_bytes() == key
    assert (tmp_path / "a.compiled").read_bytes() == (tmp_path / "b.compiled").read_bytes()


@pytest.mark.parametrize("where", ["magic", "signature", "version", "first payload byte", "last payload byte"])
def test_a_cache_with_any_byte_changed_is_refused_before_pytorch_sees_it(tmp_path, handed, where):
    path = tmp_path / "look.compiled"
    tg.io.save_compile_cache(path)
    data = bytearray(path.read_bytes())
    at = {"magic": 0, "signature": len(MAGIC) + 5, "version": len(MAGIC) + 32,
          "first payload byte": len(data) - len(b"artifacts of a compile"), "last payload byte": len(data) - 1}[where]
    data[at] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="refused, nothing loaded"):
        tg.io.load_compile_cache(path)
    assert handed == []


def test_a_cache_signed_by_another_key_or_by_none_is_refused(tmp_path, monkeypatch, handed):
    path = tmp_path / "look.compiled"
    tg.io.save_compile_cache(path)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "another user"))
    with pytest.raises(ValueError, match="this user has no key"):
        tg.io.load_compile_cache(path)
    assert not (tmp_path / "another user").exists()  # loading makes no key
    tg.io.save_compile_cache(tmp_path / "theirs.compiled")
    with pytest.raises(ValueError, match="signature does not match this user's key"):
        tg.io.load_compile_cache(path)
    assert handed == []


def test_a_file_pytorch_wrote_without_a_signature_is_refused(tmp_path, handed):
    """As ``save_compile_cache`` wrote them before they were signed: PyTorch's bytes alone."""
    tg.io.save_compile_cache(tmp_path / "made a key.compiled")
    (tmp_path / "raw.compiled").write_bytes(b"artifacts of a compile")
    with pytest.raises(ValueError, match="not a signed torchgrade compile cache"):
        tg.io.load_compile_cache(tmp_path / "raw.compiled")
    assert handed == []


@pytest.mark.parametrize("change", ["folder open to the group", "key readable by others", "key a link",
                                    "folder a link", "key of another user", "key cut short"])
def test_a_key_that_others_could_read_or_write_is_not_used(tmp_path, key_folder, monkeypatch, handed, change):
    path = tmp_path / "look.compiled"
    tg.io.save_compile_cache(path)
    key = key_folder / KEY_NAME
    if change == "folder open to the group":
        key_folder.chmod(0o770)
    elif change == "key readable by others":
        key.chmod(0o644)
    elif change == "key a link":
        (key_folder / "elsewhere").write_bytes(key.read_bytes())
        (key_folder / "elsewhere").chmod(0o600)
        key.unlink()
        key.symlink_to(key_folder / "elsewhere")
    elif change == "folder a link":
        key_folder.rename(tmp_path / "config" / "moved")
        key_folder.symlink_to(tmp_path / "config" / "moved")
    elif change == "key of another user":
        monkeypatch.setattr(os, "geteuid", lambda: os.getuid() + 1)
    else:
        key.write_bytes(key.read_bytes()[:16])
    with pytest.raises(ValueError, match="key"):
        tg.io.load_compile_cache(path)
    with pytest.raises(ValueError, match="key"):
        tg.io.save_compile_cache(tmp_path / "again.compiled")
    assert handed == [] and not (tmp_path / "again.compiled").exists()


def test_a_cache_this_user_signed_under_another_torch_warns_and_loads_nothing(tmp_path, monkeypatch, handed):
    path = tmp_path / "look.compiled"
    monkeypatch.setattr(torch, "__version__", "1.0.0")
    tg.io.save_compile_cache(path)
    monkeypatch.undo()
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    with pytest.warns(RuntimeWarning, match="written by torch 1.0.0"):
        assert tg.io.load_compile_cache(path) is False
    assert handed == []


def test_a_compile_cache_is_checked_before_it_is_read(tmp_path):
    with pytest.raises(FileNotFoundError):
        tg.io.load_compile_cache(tmp_path / "missing.compiled")
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(ValueError, match="not a regular file"):
        tg.io.load_compile_cache(tmp_path / "pipe")


def torch_artifacts(entries: dict) -> bytes:
    """``{kind: [(key, content)]}`` in PyTorch's cache-artifact format, made by PyTorch's own serializer."""
    from torch.compiler._cache import CacheArtifactFactory, CacheArtifactManager, _serialize_single_cache
    from torch.utils._appending_byte_serializer import AppendingByteSerializer

    CacheArtifactManager._ensure_cache_artifacts_registered()
    serializer = AppendingByteSerializer(serialize_fn=_serialize_single_cache)
    serializer.extend((kind, [CacheArtifactFactory.create(kind, key, content) for key, content in pairs])
                      for kind, pairs in entries.items())
    return serializer.to_bytes()


def torch_entries(payload: bytes) -> dict:
    """The inverse of :func:`torch_artifacts`, by PyTorch's own deserializer."""
    from torch.compiler._cache import CacheArtifactManager

    return {kind: [(a.key, a.content) for a in artifacts] for kind, artifacts in CacheArtifactManager.deserialize(payload).items()}


def test_an_entry_keyed_by_an_absolute_path_is_refused_and_nothing_is_written_outside(tmp_path, monkeypatch):
    """Handed to PyTorch, an ``inductor`` entry whose key is an absolute path is written there, outside Inductor's
    cache folder; through the loader, neither as PyTorch wrote it nor in a signed file's clothes."""
    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path / "inductor"))

    def attack(folder):
        return torch_artifacts({"inductor": [(str(folder / "planted"), b"anything")]})

    with contextlib.suppress(pickle.UnpicklingError):  # written first, then unpickled (its Triton bundle) as it loads
        torch.compiler.load_cache_artifacts(attack(tmp_path / "pytorch's"))
    assert len(list((tmp_path / "pytorch's" / "planted").iterdir())) == 1  # the attack, as PyTorch takes it
    raw, genuine = tmp_path / "raw.compiled", signed(b"", user_key(create=True))  # a key: the refusal is the signature's
    raw.write_bytes(attack(tmp_path / "outside"))
    dressed = tmp_path / "dressed.compiled"
    dressed.write_bytes(genuine[:len(MAGIC) + 32] + f"{torch.__version__}\n".encode() + attack(tmp_path / "outside"))
    before = sorted(tmp_path.rglob("*"))
    for path in (raw, dressed):
        with pytest.raises(ValueError, match="refused, nothing loaded"):
            tg.io.load_compile_cache(path)
    assert sorted(tmp_path.rglob("*")) == before and not (tmp_path / "outside").exists()


COMPILE = """
import os, sys, torch, torchgrade as tg
role, paths = sys.argv[1], sys.argv[2:]
if role == "load":
    assert tg.io.load_compile_cache(paths[0])
if role == "refused":
    for path in paths:
        try:
            tg.io.load_compile_cache(path)
            raise SystemExit(f"{path} loaded")
        except ValueError as error:
            print(error, file=sys.stderr)
    assert not any(files for _, _, files in os.walk(os.environ["TORCHINDUCTOR_CACHE_DIR"])), "written into the cache"
stage = tg.ToneMap("reinhard")
image = torch.rand(1, 3, 8, 8)
with torch.no_grad():
    assert torch.allclose(tg.compile(stage)(image), stage(image), atol=1e-6)
if role == "save":
    assert tg.io.save_compile_cache(paths[0])
"""


def compile_in_a_new_process(tmp_path, role: str, key_home, *paths) -> subprocess.CompletedProcess:
    """A fresh process with an empty Inductor cache of its own and ``key_home`` as its key's home, which compiles the
    reinhard tone mapper after ``role`` (save, load, refused) has had ``paths``."""
    environment = {**os.environ, "TORCHINDUCTOR_CACHE_DIR": str(tmp_path / f"inductor-{role}"), "XDG_CONFIG_HOME": str(key_home)}
    return subprocess.run([sys.executable, "-c", COMPILE, role, *map(str, paths)], env=environment, capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def genuine(tmp_path_factory):
    """A cache this user saved after compiling the reinhard tone mapper, and its key's home."""
    folder = tmp_path_factory.mktemp("genuine")
    path = folder / "reinhard.compiled"
    run = compile_in_a_new_process(folder, "save", folder / "config", path)
    assert run.returncode == 0, run.stderr[-2000:]
    return path, folder / "config"


def test_a_saved_compile_cache_loads_in_another_process(tmp_path, genuine):
    """The signed file, in a fresh process with an empty Inductor cache: PyTorch takes it, the compiled stage gives the
    eager pixels."""
    path, key_home = genuine
    run = compile_in_a_new_process(tmp_path, "load", key_home, path)
    assert run.returncode == 0, run.stderr[-2000:]


class Planted:
    """A pickle that creates ``marker`` when it is loaded: what a shell command would do, made visible."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return open, (self.marker, "w")


def test_a_cache_whose_entries_were_replaced_by_a_pickle_is_refused_and_the_pickle_never_runs(tmp_path, monkeypatch, genuine):
    """The genuine file's entries, each replaced by a pickle that creates a marker: PyTorch alone takes it and runs the
    pickle as it loads (an Inductor entry's Triton bundle is unpickled there; the compile unpickles the rest); the loader
    refuses it, raw or behind the genuine file's signature, writes nothing into Inductor's cache, and the next compile
    runs clean."""
    path, key_home = genuine
    version, payload = verified(path.read_bytes(), user_key(key_home / "torchgrade"), path)
    marker = tmp_path / "the pickle ran"
    attack = torch_artifacts({kind: [(key, pickle.dumps(Planted(marker))) for key, _ in pairs]
                              for kind, pairs in torch_entries(payload).items()})
    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path / "inductor-pytorch"))
    with contextlib.suppress(AttributeError):  # the planted object is no graph
        torch.compiler.load_cache_artifacts(attack)
    assert marker.exists()  # the attack is real
    marker.unlink()
    raw, dressed = tmp_path / "raw.compiled", tmp_path / "dressed.compiled"
    raw.write_bytes(attack)
    dressed.write_bytes(path.read_bytes()[:len(MAGIC) + 32] + f"{version}\n".encode() + attack)
    run = compile_in_a_new_process(tmp_path, "refused", key_home, raw, dressed)
    assert run.returncode == 0 and run.stderr.count("refused, nothing loaded") == 2, run.stderr[-2000:]
    assert not marker.exists()
