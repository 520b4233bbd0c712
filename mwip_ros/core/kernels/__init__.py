"""Many scenarios at once: the batch simulator over numpy arrays and compiled by numba from the scalar loop's own
functions, its numba cache and SIMD lanes, and the memory budget of the offline tools.
"""
