#version 430
// Hao & Varshney's bleeding pass (2004, Secs. 2.3, 3.1): per scattering vertex x_o, the sum
// over its precomputed scattering neighbourhood N(x_o) (compressed rows, dipole_gl/vertex.py):
//   dipole:  B_o = sum_j w_oj Phi_j,  w_oj = R_d(|x_j - x_o|)/pi precomputed per pair and colour
//   dirpole: B_o = sum_j sum_l S_d(x_j, w_12,jl; x_o) Phi_jl   (kernel evaluated per frame)
// The exit Fresnel transmittance is applied per pixel (shade_vertex.frag).
// Each row runs in chunks (positions u_k0 .. u_k1 - 1 within the row), one dispatch each, so that no
// invocation exceeds the loop budget of dipole_gl/budget.py (llvmpipe ends an invocation's loops after
// 65,535 iterations in all, silently); the partial sums accumulate in b_out.
// KERNEL_DIRPOLE and MAX_LIGHTS are #defined. Mirrors dipole_gl/twin.py: vertex_gather().
layout(local_size_x = 64) in;
#include "sh.glsl"
#include "kernels.glsl"
#include "medium.glsl"

layout(std430, binding = 0) readonly buffer Points  { vec4 pos_area[]; };
layout(std430, binding = 1) readonly buffer Normals { vec4 nrm[]; };
layout(std430, binding = 2) readonly buffer Flux    { vec4 flux[]; };
layout(std430, binding = 3) readonly buffer Dirs    { vec4 w12[]; };
layout(std430, binding = 4) readonly buffer Total   { vec4 total[]; };
layout(std430, binding = 5) readonly buffer Offsets { int offsets[]; };
layout(std430, binding = 6) readonly buffer Nbrs    { int nbrs[]; };
layout(std430, binding = 7) readonly buffer Factors { vec4 factors[]; };
layout(std430, binding = 8) buffer Out              { vec4 b_out[]; };

uniform int u_count;
uniform int u_k0;                    // this dispatch's neighbours: row positions u_k0 .. u_k1 - 1
uniform int u_k1;
uniform int u_n_lights;

void main()
{
    int o = int(gl_GlobalInvocationID.x);
    if (o >= u_count) return;
    vec3 sum = u_k0 == 0 ? vec3(0.0) : b_out[o].rgb;
#if KERNEL_DIRPOLE
    vec3 xo = pos_area[o].xyz;
    vec3 no = nrm[o].xyz;
    Coeffs c = coeffs_at(xo, no);
#endif
    int end = min(offsets[o + 1], offsets[o] + u_k1);
    for (int k = offsets[o] + u_k0; k < end; ++k) {
        int j = nbrs[k];
#if KERNEL_DIRPOLE
        for (int l = 0; l < u_n_lights; ++l) {
            vec4 f = flux[l * u_count + j];
            if (f.a > 0.0) sum += dirpole_sd(pos_area[j].xyz, nrm[j].xyz, w12[l * u_count + j].xyz, xo, no, c) * f.rgb;
        }
#else
        sum += factors[k].rgb * total[j].rgb;
#endif
    }
    b_out[o] = vec4(sum, 0.0);
}
