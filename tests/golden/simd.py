"""numpy's AVX-512 loops (sin, cos, exp, ...) round differently in the last bit from its AVX2 loops, and now and
then one bit is an RTCM least significant bit: the golden files are written and compared with numpy held to the
AVX2 level (x86-64-v3), in a process of their own when this one runs with AVX-512 (NPY_DISABLE_CPU_FEATURES,
read by numpy at import)."""

from __future__ import annotations

import os

ENV = "NPY_DISABLE_CPU_FEATURES"
# set in the pinned process: numpy's feature table still lists what the CPU has, not what numpy dispatches to
PINNED = "AUGNET_GOLDEN_AVX2"


def avx512_on() -> list[str]:
    """numpy's AVX-512 features enabled in this process (numpy 2.4 names the level X86_V4, earlier ones AVX512_*)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_features__ as features
    return [k for k, on in features.items() if on and (k.startswith("AVX512") or k == "X86_V4")]


def needs_pinning() -> bool:
    """Whether this process runs numpy's AVX-512 loops (and golden cases must run in a process of their own)."""
    return not os.environ.get(PINNED) and bool(avx512_on())


def pinned_env() -> dict[str, str]:
    """This process's environment with numpy's AVX-512 features disabled."""
    env = dict(os.environ)
    env[ENV] = " ".join(sorted(set(env.get(ENV, "").split()) | set(avx512_on())))
    env[PINNED] = "1"
    return env
