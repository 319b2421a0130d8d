"""Model files checked before they are trusted (issue 20): a crafted file with a valid
checksum but a NaN threshold, a zero window, foreign dtypes or a huge extra array is one
ModelFileError naming the file, never a detector that cannot alarm or a 3 GB load."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from model_support import SHIPPED, craft_model, set_key

from monitor.errors import ModelFileError
from monitor.model import filecheck
from monitor.model.modelfile import load_model


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (set_key("eps0", float("nan")), "header eps0 must be a finite number"),
        (set_key("eps0", float("inf")), "header eps0 must be a finite number"),
        (set_key("eps0", 0.0), "header eps0 must be > 0"),
        (set_key("j0", -1.0), "header j0 must be >= 0"),
        (set_key("sigma", "s"), "header sigma must be a finite number"),
        (set_key("window_n", 0), "header window_n must be a whole number 1..360000"),
        (set_key("window_n", 10**11), "header window_n must be a whole number"),
        (set_key("residual_clip", [float("nan")]), "residual_clip must be null or a list"),
        (set_key("threshold", []), "header threshold must be an object"),
    ],
)
def test_header_values_are_typed_and_ranged(tmp_path, change, message) -> None:
    with pytest.raises(ModelFileError, match="crafted.npz: inconsistent model file") as exc:
        load_model(craft_model(tmp_path, header_change=change))
    assert message in str(exc.value)


@pytest.mark.parametrize("raw", [b"[]", b'"s"', b"[" * 100_000 + b"]" * 100_000])
def test_a_header_that_is_not_an_object_is_corrupt(tmp_path, raw: bytes) -> None:
    with pytest.raises(ModelFileError, match="crafted.npz: corrupt model header"):
        load_model(craft_model(tmp_path, raw_header=raw))


@pytest.mark.parametrize("dtype", [np.int8, np.complex128, np.float32])
def test_arrays_of_another_dtype_are_refused(tmp_path, dtype) -> None:
    def change(arrays):
        arrays["patterns"] = arrays["patterns"].astype(dtype)

    with pytest.raises(ModelFileError, match="array patterns is"):
        load_model(craft_model(tmp_path, arrays_change=change))


def test_a_huge_extra_array_is_not_unpacked(tmp_path, monkeypatch) -> None:
    path = craft_model(tmp_path)
    # 64 MB of zeros compress to ~64 kB; an unknown member is neither read nor counted.
    with (
        zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf,
        zf.open("patterns_extra.npy", "w", force_zip64=True) as fh,
    ):
        for _ in range(64):
            fh.write(bytes(1 << 20))
    assert path.stat().st_size < 2_000_000
    assert load_model(path).window_n > 0
    # Known members are sized from the zip directory before anything is unpacked.
    monkeypatch.setattr(filecheck, "MAX_MODEL_BYTES", 1000)
    with pytest.raises(ModelFileError, match="unpack to [0-9]+ bytes, more than 1000"):
        load_model(path)


def test_the_shipped_model_still_loads() -> None:
    m = load_model(SHIPPED)
    assert np.isfinite(m.eps0) and m.eps0 > 0 and m.window_n >= 1


def _rename_first_scaled(h):
    h.pop("validity", None)  # an older file: the envelope is derived from the patterns
    h["normalizer"]["names"][1] = None


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (_rename_first_scaled, r"the normalizer has no mean and std for PA\)"),
        (lambda h: h["spec"].update(outputs=None), r"bad DGRNN spec \{.{60,77}\.\.\.: "),
    ],
)
def test_spec_and_normalizer_disagreeing_is_one_short_line(tmp_path, change, message) -> None:
    """Found by tests/test_fuzz.py: a bare ValueError (traceback), a message quoting the spec."""
    with pytest.raises(ModelFileError, match=message) as exc:
        load_model(craft_model(tmp_path, header_change=change))
    assert "\n" not in str(exc.value) and len(str(exc.value)) < len(str(tmp_path)) + 250
