"""Kernels compiled from C on first use: cached once per source and compiler, refused from a folder others may write
to, and a clear warning (never an error) where they cannot be had, the torch form then running in their place."""

import logging
import os

import pytest
import torch

from torchgrade.lut import LUT3D
from torchgrade.lut.native import SOURCE
from torchgrade.runtime import native

compile_fresh = native.native_library.__wrapped__  # the loader without its per-process memo


def test_a_source_compiles_once_into_the_cache_and_later_loads_from_it(tmp_path, monkeypatch, caplog):
    monkeypatch.setenv(native.CACHE_VARIABLE, str(tmp_path))
    with caplog.at_level(logging.INFO, logger="torchgrade.native"):
        first = compile_fresh(SOURCE)
        libraries = sorted((tmp_path / "native").iterdir())
        second = compile_fresh(SOURCE)
    assert first is not None and second is not None and hasattr(second, "tetrahedral_float")
    assert [path.suffix for path in libraries] == [".so"]  # one library, no partial file left behind
    assert sorted((tmp_path / "native").iterdir()) == libraries
    assert sum("compiled lookup.c" in record.getMessage() for record in caplog.records) == 1
    assert oct((tmp_path / "native").stat().st_mode & 0o777) == oct(0o700)


def test_another_compiler_or_flags_make_another_library(tmp_path, monkeypatch):
    monkeypatch.setenv(native.CACHE_VARIABLE, str(tmp_path))
    compile_fresh(SOURCE)
    monkeypatch.setattr(native, "compiler_command", lambda: ["cc", "-O2", "-fPIC", "-shared", "-ffp-contract=off"])
    compile_fresh(SOURCE)
    assert len(list((tmp_path / "native").iterdir())) == 2


def test_without_a_working_compiler_the_loader_warns_and_the_torch_form_runs(tmp_path, monkeypatch):
    monkeypatch.setenv(native.CACHE_VARIABLE, str(tmp_path))
    monkeypatch.setenv("CC", "false")
    with pytest.warns(RuntimeWarning, match="lookup.c could not be compiled .*torch form"):
        assert compile_fresh(SOURCE) is None
    assert list((tmp_path / "native").iterdir()) == []  # the failed compile left nothing behind


def test_where_no_cache_folder_can_be_made_each_process_compiles_into_a_private_temporary_one(tmp_path, monkeypatch):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv(native.CACHE_VARIABLE, str(tmp_path / "file" / "below"))  # a path under a file
    library = compile_fresh(SOURCE)
    assert library is not None and hasattr(library, "tetrahedral_double")


def test_a_cache_folder_others_may_write_to_is_refused(tmp_path, monkeypatch):
    if not hasattr(os, "getuid"):
        pytest.skip("POSIX permissions only")
    monkeypatch.setenv(native.CACHE_VARIABLE, str(tmp_path))
    (tmp_path / "native").mkdir()
    (tmp_path / "native").chmod(0o777)
    with pytest.warns(RuntimeWarning, match="others may write to it"):
        assert compile_fresh(SOURCE) is None


def test_the_switch_turns_compiled_kernels_off_without_a_word(tmp_path, monkeypatch, recwarn):
    monkeypatch.setenv(native.CACHE_VARIABLE, str(tmp_path))
    monkeypatch.setenv(native.NATIVE_VARIABLE, "0")
    assert compile_fresh(SOURCE) is None
    assert not (tmp_path / "native").exists() and len(recwarn) == 0


def test_worker_threads_run_the_compiled_loop_at_once_and_give_one_threads_result():
    """ctypes lets go of the GIL during the call: two workers give the one-thread result bit for bit."""
    lut = LUT3D(torch.rand(33, 33, 33, 3))
    image = torch.rand(2, 3, 300, 301) * 1.2 - 0.1
    threads = torch.get_num_threads()
    try:
        with torch.no_grad():
            torch.set_num_threads(1)
            one = lut(image)
            torch.set_num_threads(2)
            two = lut(image)
    finally:
        torch.set_num_threads(threads)
    assert torch.equal(one, two)
