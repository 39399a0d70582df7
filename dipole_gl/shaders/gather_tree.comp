#version 430
// The hierarchical gather's far field (Jensen & Buhler 2002, Sec. 3.2): per camera pixel (exit
// point x_o of the G-buffer), a stackless depth-first descent of the octree of irradiance samples
// (dipole_gl/octree.py; nodes in depth-first order, link.z = skip, the first node after the
// subtree). At an internal node k:
//   unlit (W = 0)                                   -> skip (nothing to add)
//   its cell within rho of x_o, or A > eps |p - x_o|^2 -> refine (next node)     (dOmega > epsilon)
//   otherwise                                       -> the node's aggregate at its centroid p, skip
// A leaf is one surface sample, added exactly as the dense far field adds it (window 1 - w(r),
// gather_dense.comp); an accepted node's cell lies beyond rho, where the window is 1. At
// epsilon = 0 every lit node is refined: the dense far field over the same samples.
// The descent runs at most u_steps nodes per dispatch (dipole_gl/budget.py: llvmpipe ends an
// invocation's loops after 65,535 iterations in all, silently); the cursor, the node visits and
// the kernel evaluations persist per pixel in State, the partial sum in Accum, and every pixel
// not yet done counts itself in Pending so that the host dispatches again. The last pass (near
// field, exit Fresnel, images) is gather_dense.comp's last dispatch over Accum.
// KERNEL_DIRPOLE and MAX_LIGHTS are #defined by the host. Mirrors dipole_gl/twin_tree.py.
layout(local_size_x = 8, local_size_y = 8) in;
#include "sh.glsl"
#include "optics.glsl"
#include "kernels.glsl"
#include "medium.glsl"

layout(std430, binding = 0) readonly buffer Points  { vec4 pos_area[]; };  // the samples in Morton order
layout(std430, binding = 1) readonly buffer Normals { vec4 nrm[]; };
layout(std430, binding = 2) readonly buffer Flux    { vec4 flux[]; };      // [l * u_count + s]: rgb, a = V
layout(std430, binding = 3) readonly buffer Dirs    { vec4 w12[]; };
layout(std430, binding = 4) readonly buffer Total   { vec4 total[]; };
layout(std430, binding = 5) buffer Accum            { vec4 accum[]; };     // per pixel: the far field so far
layout(std430, binding = 6) readonly buffer Cells   { vec4 cell[]; };      // per node: cell centre, half size
layout(std430, binding = 7) readonly buffer Links   { ivec4 link[]; };     // per node: first, end, skip, internal (-1: leaf)
layout(std430, binding = 8) readonly buffer Geom    { vec4 geom[]; };      // 3 per internal node: centroid, area |
                                                                           //   normal, W | total flux
layout(std430, binding = 9) readonly buffer Lights  { vec4 agg[]; };       // 2 per (light, internal node): flux | w_i
layout(std430, binding = 10) buffer State           { ivec4 state[]; };    // per pixel: cursor, visits, evaluations
layout(std430, binding = 11) buffer Pending         { uint pending; };

layout(binding = 3) uniform sampler2D u_gpos;     // xyz, w = coverage
layout(binding = 4) uniform sampler2D u_gnrm;

uniform int u_count;                 // surface samples (the stride of the per-light buffers)
uniform int u_nodes;
uniform int u_internal;              // internal nodes (the stride of Lights)
uniform int u_steps;                 // nodes per invocation and dispatch
uniform int u_n_lights;
uniform float u_eta;
uniform float u_epsilon;             // the solid-angle bound
uniform float u_rho;                 // the near-field radius (3 x sample spacing)
uniform ivec2 u_size;

void main()
{
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    vec4 gp = texelFetch(u_gpos, px, 0);
    if (gp.w < 0.5) return;
    int pix = px.y * u_size.x + px.x;
    ivec4 st = state[pix];
    if (st.x >= u_nodes) return;
    vec3 xo = gp.xyz;
    vec3 no = normalize(texelFetch(u_gnrm, px, 0).xyz);
    Coeffs c = coeffs_at(xo, no);
    vec3 sum = accum[pix].rgb;
    int i = st.x;                    // the cursor
    int steps = 0;
    int evals = 0;
    while (i < u_nodes && steps < u_steps) {
        ++steps;
        ivec4 ln = link[i];
        if (ln.w < 0) {
            // ---- a leaf: sample ln.x, as the dense far field
            int s = ln.x;
            vec3 xi = pos_area[s].xyz;
            float far = smoothstep(0.0, u_rho, length(xi - xo));
            if (far > 0.0) {
#if KERNEL_DIRPOLE
                vec3 ni = nrm[s].xyz;
                for (int l = 0; l < u_n_lights; ++l) {
                    vec4 f = flux[l * u_count + s];
                    if (f.a > 0.0) sum += far * dirpole_sd(xi, ni, w12[l * u_count + s].xyz, xo, no, c) * f.rgb;
                }
#else
                vec3 t = total[s].rgb;
                if (t != vec3(0.0)) sum += far * rd_dipole(length(xi - xo), c) * t;
#endif
                ++evals;
            }
            i = ln.z;
            continue;
        }
        int k = ln.w;
        vec4 g0 = geom[3 * k];           // centroid, area
        vec4 g1 = geom[3 * k + 1];       // normal, W
        if (g1.w <= 0.0) {               // unlit: nothing below adds light
            i = ln.z;
            continue;
        }
        vec4 cl = cell[i];
        vec3 dq = max(abs(xo - cl.xyz) - cl.w, vec3(0.0));
        vec3 dp = g0.xyz - xo;
        float d2 = dot(dp, dp);
        if (dot(dq, dq) < u_rho * u_rho || g0.w > u_epsilon * d2) {
            i += 1;                      // refine: the first child is the next node
            continue;
        }
        // ---- accept: the node's aggregate as one source at its centroid
#if KERNEL_DIRPOLE
        for (int l = 0; l < u_n_lights; ++l) {
            vec4 f = agg[2 * (l * u_internal + k)];
            vec3 w;                      // the mean direction to the light, refracted at the mean normal
            if (f.rgb != vec3(0.0) && refract_dir(-agg[2 * (l * u_internal + k) + 1].xyz, g1.xyz, u_eta, w))
                sum += dirpole_sd(g0.xyz, g1.xyz, w, xo, no, c) * f.rgb;
        }
#else
        sum += rd_dipole(sqrt(d2), c) * geom[3 * k + 2].rgb;
#endif
        ++evals;
        i = ln.z;
    }
    accum[pix] = vec4(sum, 0.0);
    state[pix] = ivec4(i, st.y + steps, st.z + evals, 0);
    if (i < u_nodes) atomicAdd(pending, 1u);
}
