"""Print the names of numpy's AVX-512 dispatch targets, for NPY_DISABLE_CPU_FEATURES (make test-no-avx512):
X86_V4, AVX512_ICL, AVX512_SPR in numpy 2.4; AVX512F, AVX512_SKX, ... in older releases."""

try:
    from numpy._core._multiarray_umath import __cpu_dispatch__ as dispatch
except ImportError:  # numpy 1.x
    from numpy.core._multiarray_umath import __cpu_dispatch__ as dispatch

print(" ".join(name for name in dispatch if "AVX512" in name or name == "X86_V4"))
