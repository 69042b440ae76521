"""libLLVM selection and backend set-up."""
import os

from relight import backend


def test_choice_is_at_least_17():
    path = backend.choose_libllvm()
    version = backend._llvm_version_of(path)
    assert version is not None and version[0] >= backend.MIN_LLVM_MAJOR


def test_candidates_skip_old_system_llvm():
    for path in backend.llvm_candidates():
        major = backend._major_from_name(path)
        assert major == 0 or major >= backend.MIN_LLVM_MAJOR or "/usr/" not in path


def test_initialised_backend_reports_good_llvm(mi):
    dr = backend.drjit()
    assert tuple(dr.detail.llvm_version())[0] >= backend.MIN_LLVM_MAJOR
    assert dr.thread_count() >= 1
    assert os.environ["DRJIT_CACHE_DIR"]
    assert "llvm_ad_rgb" in backend.describe() or "cuda_ad_rgb" in backend.describe()
