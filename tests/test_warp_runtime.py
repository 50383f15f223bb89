"""The recorded relaunch of a CPU kernel (`solvers.warp_runtime.RecordedLaunch`): its argument structure built once
and the compiled kernel called on it gives what warp's own launch gives, bit for bit, and follows every change of a
scalar argument and of the launch size; a backend's launches through `Relaunches` (one recording per kernel, size
and arrays) the same; and warp's initialisation without its no-CUDA-driver notice."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import warp as wp

from frictionbench.solvers import warp_runtime
from frictionbench.solvers.warp_runtime import RecordedLaunch, Relaunches, init_warp

init_warp()


@wp.kernel
def _affine(x: wp.array(dtype=wp.float64), a: wp.float64, b: wp.float64, out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = wp.sin(a * x[i]) + b * x[i] * x[i]


def _warp_launch(x: np.ndarray, a: float, b: float, n: int) -> np.ndarray:
    """The kernel launched by warp itself on the first n entries of x, into a fresh zero output."""
    out = wp.zeros(x.size, dtype=wp.float64, device="cpu")
    wp.launch(_affine, n, inputs=[wp.array(x, dtype=wp.float64, device="cpu"), a, b, out], device="cpu")
    return out.numpy()


@pytest.mark.parametrize("packed", [True, False], ids=["built-once", "warp-relaunch"])
def test_a_relaunch_matches_warps_launch_bit_for_bit_through_every_change(monkeypatch, packed: bool) -> None:
    if not packed:
        monkeypatch.setattr(warp_runtime, "_build_cpu_args_structs", None)
    elif warp_runtime._build_cpu_args_structs is None:
        pytest.fail("this warp has no _build_cpu_args_structs: the CPU relaunch falls back to warp's")
    x = np.random.default_rng(3).uniform(-2.0, 2.0, 37)
    xa = wp.array(x, dtype=wp.float64, device="cpu")
    out = wp.zeros(x.size, dtype=wp.float64, device="cpu")
    launch = RecordedLaunch(_affine, x.size, [xa, 1.0, 0.0, out], "cpu")
    view = out.numpy()
    for a, b, n in [(1.0, 0.0, 37), (0.7, 0.0, 37), (0.7, -1.3, 37), (0.7, -1.3, 11), (2.5, 0.25, 11), (2.5, 0.25, 37)]:
        launch.set(1, a)
        launch.set(2, b)
        view[:] = 0.0
        launch.launch(n)
        expected = _warp_launch(x, a, b, n)
        assert np.array_equal(view, expected), (a, b, n)
        assert np.count_nonzero(view[n:]) == 0  # the size is followed: nothing written past n
    assert (launch._packed is not None) == packed


def test_relaunches_keep_one_recording_per_kernel_size_and_arrays_and_follow_the_scalars() -> None:
    """Launches through `Relaunches` on two input arrays, at changing scalars and two sizes, give warp's own launch
    bit for bit into the same output; each (size, input array) pair is one recording, the scalars set on it."""
    rng = np.random.default_rng(5)
    xs = [rng.uniform(-2.0, 2.0, 29) for _ in range(2)]
    arrays = [wp.array(x, dtype=wp.float64, device="cpu") for x in xs]
    out = wp.zeros(29, dtype=wp.float64, device="cpu")
    launches = Relaunches("cpu")
    view = out.numpy()
    calls = [(0, 1.0, 0.0, 29), (1, 1.0, 0.0, 29), (0, 0.3, 2.0, 29), (1, -0.4, 0.5, 29), (0, 0.3, 2.0, 13),
             (0, 1.1, -2.0, 13), (1, 0.9, 0.1, 29), (0, 0.0, 0.0, 0)]
    for k, a, b, n in calls:
        view[:] = 0.0
        launches.launch(_affine, n, [arrays[k], a, b, out])
        expected = _warp_launch(xs[k], a, b, n) if n else np.zeros(29)
        assert np.array_equal(view, expected), (k, a, b, n)
    assert len(launches._recorded) == 3  # (29, x0), (29, x1), (13, x0); a size-0 launch records nothing


def test_warps_no_driver_notice_is_dropped_and_other_native_output_kept(capfd) -> None:
    """`without_lines` drops the lines native code writes to file descriptor 2 that start with the prefix (warp's
    notice that no CUDA driver loads, printed at every `wp.init()` on a CPU machine) and writes back the rest."""
    from frictionbench.solvers.warp_runtime import NO_CUDA_DRIVER, without_lines

    def native() -> None:
        os.write(2, f"{NO_CUDA_DRIVER}. GPU execution will not be available.\nanother native message\n".encode())

    without_lines(NO_CUDA_DRIVER, native)
    err = capfd.readouterr().err
    assert NO_CUDA_DRIVER not in err and "another native message\n" in err


def test_a_fresh_process_initialises_warp_without_the_notice() -> None:
    code = "from frictionbench.solvers.warp_runtime import init_warp; init_warp(); print('ok')"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "ok" and "CUDA driver" not in done.stderr
