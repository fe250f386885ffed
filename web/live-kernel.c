/* The live page's inner loop (web/live-worker.js) as WebAssembly with 128-bit SIMD: a gather along the
 * links of each receiver, y_r = sum over r's links l of F_l x_src(l), three channels in double.
 * The same order of operations as the worker's JavaScript loop (a multiply, then an add, link by link,
 * no fused multiply-add), so both give the same doubles; the worker falls back to its own loop where
 * WebAssembly is missing. Built by CMake with clang --target=wasm32 and wasm-ld when both are found
 * (Debian's clang and lld), embedded in the page; no C library, memory given by the worker. */
#include <stdint.h>
#include <wasm_simd128.h>

/* Rows [0, n): start[n + 1] offsets into src and F; x and y hold 4 doubles per node (r, g, b, unused);
 * rows with skip[r] != 0 (a cluster's: the worker gathers its vectors itself) get zeros. */
__attribute__((export_name("gather"))) void gather(uint32_t n, const uint32_t *start, const uint32_t *src,
                                                   const float *F, const uint8_t *skip, const double *x, double *y)
{
    for (uint32_t r = 0; r < n; r++) {
        v128_t rg = wasm_f64x2_splat(0.0), b = wasm_f64x2_splat(0.0);
        if (!skip[r]) {
            for (uint32_t l = start[r], e = start[r + 1]; l < e; l++) {
                const v128_t f = wasm_f64x2_splat((double)F[l]);
                const double *s = x + 4 * (uintptr_t)src[l];
                rg = wasm_f64x2_add(rg, wasm_f64x2_mul(f, wasm_v128_load(s)));
                b = wasm_f64x2_add(b, wasm_f64x2_mul(f, wasm_v128_load(s + 2)));
            }
        }
        wasm_v128_store(y + 4 * (uintptr_t)r, rg);
        wasm_v128_store(y + 4 * (uintptr_t)r + 2, b);
    }
}
