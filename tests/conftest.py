import os

# The suite's cost is mostly XLA compilation. It compiles at LLVM's -O0 (XLA's HLO passes and
# fusion still run): measured on this repository's default suite, -n 2, the same 2-core machine
# (2026-12-06): 660.6 s at the default level, 550.5 s at 0. The numbers move by float32
# rounding only (FMA contraction differs): tolerances are from theory, "same bits" tests compare
# within one run, and subprocesses inherit the flag. A level the caller sets in XLA_FLAGS wins.
# Must run before JAX creates its backend (the first computation), which no import does.
if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                               + " --xla_backend_optimization_level=0").strip()

import jax  # noqa: E402
import pytest  # noqa: E402

# Strict promotion catches accidental float64/int mixing in the library (STYLE: equinox tests).
jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")


@pytest.fixture
def getkey():
    """A fresh, deterministic key per call within a test."""
    state = {"key": jax.random.key(20261122)}

    def _next():
        state["key"], sub = jax.random.split(state["key"])
        return sub

    return _next


@pytest.fixture(autouse=True)
def _library_errors_only(request):
    """Tests marked ``library_errors`` check the library's own errors (the ``ValueError`` or
    ``TypeError`` that names what was expected and what came): what a user sees, who runs
    without jaxtyping's import hook. The suite runs with the hook on (pyproject's
    ``--jaxtyping-packages``), whose check of an annotation would fire first; it is off during
    such a test (``jaxtyping_disable`` is read at each call; ``helpers.library_errors()`` turns
    them off for one call)."""
    if request.node.get_closest_marker("library_errors") is None:
        yield
        return
    from helpers import library_errors

    with library_errors():
        yield


@pytest.fixture(autouse=True, scope="session")
def _private_user_cache(tmp_path_factory):
    """Tables built on demand during the tests go to this session's own cache, never the
    user's ``~/.cache`` (the suite must not depend on, or leave behind, what an earlier run
    built there); subprocesses inherit it."""
    import os

    old = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(tmp_path_factory.mktemp("xdg_cache"))
    yield
    if old is None:
        os.environ.pop("XDG_CACHE_HOME", None)
    else:
        os.environ["XDG_CACHE_HOME"] = old


def _map_count() -> int:
    """This process's memory mappings (Linux ``/proc/self/maps`` lines; 0 elsewhere)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\n")
    except OSError:
        return 0


def _map_budget() -> int:
    """Half the kernel's per-process mapping limit (``vm.max_map_count``, 65530 by default)."""
    try:
        with open("/proc/sys/vm/max_map_count") as f:
            return int(f.read()) // 2
    except (OSError, ValueError):
        return 32765


@pytest.fixture(autouse=True)
def _bounded_compiled_code(request):
    """After a slow test, drop JAX's compiled executables once the process holds more than
    half of ``vm.max_map_count`` memory mappings. XLA:CPU keeps each executable's JIT code in
    mappings of its own (about 600 per light-warp sweep case), released only with the
    executable; a long process that reaches the limit crashes (SIGSEGV, or LLVM's "Unable to
    allocate section memory" abort) when the next compilation's mmap fails: the one-process
    light-warp sweep did, near its end. Only slow tests check (reading the map costs ~5 ms),
    so the default suite is unchanged; results do not depend on the caches."""
    yield
    if request.node.get_closest_marker("slow") is not None and _map_count() > _map_budget():
        import gc

        jax.clear_caches()
        gc.collect()


_SHARED_CACHE = "ANISOSAMPLE_TESTS_COMPILATION_CACHE"


def pytest_configure(config):
    """One persistent compilation cache per test run, shared by the run's pytest-xdist workers:
    the suite's cost is mostly XLA compilation, and the two workers compile many of the same
    programs (the same scenes, warps and sets in tests that land on different workers). The
    controller makes the directory before the workers start (they inherit the environment) and
    removes it at the end; the cache holds executables only, so results are the same bits.
    Subprocesses the tests start do not read it (the variable is ours, not JAX's)."""
    import os
    import tempfile

    if not hasattr(config, "workerinput") and _SHARED_CACHE not in os.environ:
        os.environ[_SHARED_CACHE] = tempfile.mkdtemp(prefix="anisosample-jax-cache-")
        config._anisosample_cache_owner = True
    jax.config.update("jax_compilation_cache_dir", os.environ[_SHARED_CACHE])
    # Measured on four render/warp test files (-n 2, quiet machine): user CPU 439 s without the
    # cache, 371 s keeping programs that compile in >= 0.5 s, 410 s at 0.1 s, 411 s at 1.0 s.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)


def pytest_unconfigure(config):
    import os
    import shutil

    if getattr(config, "_anisosample_cache_owner", False):
        shutil.rmtree(os.environ.pop(_SHARED_CACHE), ignore_errors=True)
