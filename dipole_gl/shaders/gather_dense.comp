#version 430
// The dense gather: per camera pixel (exit point x_o of the G-buffer), the kernel integrated over
// the WHOLE surface, then the exit Fresnel transmittance:
//   dipole:  L = T(w_o)/pi int R_d(|x_i - x_o|) E_t(x_i) dA          (Jensen et al. 2001, Eq. 5)
//   dirpole: L = T(w_o) sum_l int S_d(x_i, w_12,l; x_o) E_t,l(x_i) dA  (Frisvad et al. 2014)
// with the material at the exit point, split by the window w(r) = 1 - smoothstep(0, rho, r)
// (docs/dipole_rivals.md, Sec. "The dense gather"):
//   far field  (1 - w) K: every surface sample (dipole_gl/sampling.py), the midpoint rule;
//   near field w K: a polar quadrature on the tangent plane at x_o with the irradiance of x_o
//   (radial Gauss-Legendre panels u_rad_t/u_rad_w on [0, rho], u_n_phi angles).
// The far field runs in chunks, one dispatch each (samples u_first .. u_end - 1), so that no
// invocation exceeds the loop budget of dipole_gl/budget.py (llvmpipe ends an invocation's loops
// after 65,535 iterations in all, silently). The partial sums accumulate per pixel in Accum; the
// last dispatch (u_last = 1) adds the near field and writes the images.
// KERNEL_DIRPOLE and MAX_LIGHTS are #defined by the host. Mirrors dipole_gl/twin.py: dense_gather().
layout(local_size_x = 8, local_size_y = 8) in;
#include "sh.glsl"
#include "optics.glsl"
#include "kernels.glsl"
#include "medium.glsl"

layout(std430, binding = 0) readonly buffer Points  { vec4 pos_area[]; };
layout(std430, binding = 1) readonly buffer Normals { vec4 nrm[]; };
layout(std430, binding = 2) readonly buffer Flux    { vec4 flux[]; };
layout(std430, binding = 3) readonly buffer Dirs    { vec4 w12[]; };
layout(std430, binding = 4) readonly buffer Total   { vec4 total[]; };
layout(std430, binding = 5) buffer Accum            { vec4 accum[]; };   // per pixel: the far field so far

layout(binding = 3) uniform sampler2D u_gpos;     // xyz, w = coverage
layout(binding = 4) uniform sampler2D u_gnrm;
layout(binding = 5) uniform sampler2D u_grefl;    // direct reflection
layout(binding = 6) uniform sampler2D u_gvis0;    // visibility of lights 0-3 at x_o
layout(binding = 7) uniform sampler2D u_gvis1;    // lights 4-7
layout(rgba32f, binding = 0) writeonly uniform image2D u_sub;
layout(rgba32f, binding = 1) writeonly uniform image2D u_full;

uniform int u_count;                 // surface samples (the stride of the per-light buffers)
uniform int u_first;                 // this dispatch's samples: u_first .. u_end - 1
uniform int u_end;
uniform int u_last;                  // 1: the last dispatch (near field, Fresnel, images)
uniform int u_n_lights;
uniform float u_eta;
uniform vec3 u_cam_pos;
uniform ivec2 u_size;
uniform float u_rho;                 // near-field radius (3 x sample spacing)
uniform int   u_n_rad;
uniform float u_rad_t[N_RAD];        // radial nodes on [0, 1] (times rho)
uniform float u_rad_w[N_RAD];        // their weights (for int_0^1 dt)
uniform int   u_n_phi;               // angles of the near-field quadrature
uniform vec3  u_light_pos[MAX_LIGHTS];
uniform vec3  u_light_I[MAX_LIGHTS];

// Transmitted irradiance of light l at the exit point (the near field's E_t), and its direction.
vec3 irradiance_at(int l, vec3 xo, vec3 no, float vis, out vec3 wi)
{
    vec3 to_l = u_light_pos[l] - xo;
    float d2 = dot(to_l, to_l);
    wi = to_l * inversesqrt(d2);
    float c = dot(wi, no);
    if (c <= 0.0 || vis <= 0.0) return vec3(0.0);
    return u_light_I[l] * (c * fresnel_transmittance(c, u_eta) * vis / d2);
}

void main()
{
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    vec4 gp = texelFetch(u_gpos, px, 0);
    if (gp.w < 0.5) {
        if (u_last == 1) {
            imageStore(u_sub, px, vec4(0.0));
            imageStore(u_full, px, vec4(0.0));
        }
        return;
    }
    int pix = px.y * u_size.x + px.x;
    vec3 xo = gp.xyz;
    vec3 no = normalize(texelFetch(u_gnrm, px, 0).xyz);
    Coeffs c = coeffs_at(xo, no);
    vec3 sum = u_first == 0 ? vec3(0.0) : accum[pix].rgb;
    // ---- far field: this chunk's surface samples, weighted by 1 - w(r)
    for (int i = u_first; i < u_end; ++i) {
        vec3 xi = pos_area[i].xyz;
        float far = smoothstep(0.0, u_rho, length(xi - xo));
        if (far == 0.0) continue;
#if KERNEL_DIRPOLE
        vec3 ni = nrm[i].xyz;
        for (int l = 0; l < u_n_lights; ++l) {
            vec4 f = flux[l * u_count + i];
            if (f.a > 0.0) sum += far * dirpole_sd(xi, ni, w12[l * u_count + i].xyz, xo, no, c) * f.rgb;
        }
#else
        vec3 t = total[i].rgb;
        if (t != vec3(0.0)) sum += far * rd_dipole(length(xi - xo), c) * t;
#endif
    }
    if (u_last == 0) {
        accum[pix] = vec4(sum, 0.0);
        return;
    }
    // ---- near field: w(r) K on the tangent plane at x_o, with the irradiance at x_o
    vec4 v0 = texelFetch(u_gvis0, px, 0), v1 = texelFetch(u_gvis1, px, 0);
    float vis[8] = float[8](v0.x, v0.y, v0.z, v0.w, v1.x, v1.y, v1.z, v1.w);
#if KERNEL_DIRPOLE
    vec3 t1 = normalize(abs(no.x) < 0.9 ? cross(no, vec3(1.0, 0.0, 0.0)) : cross(no, vec3(0.0, 1.0, 0.0)));
    vec3 t2 = cross(no, t1);
    for (int l = 0; l < u_n_lights; ++l) {
        vec3 wi;
        vec3 e = irradiance_at(l, xo, no, vis[l], wi);
        if (e == vec3(0.0)) continue;
        vec3 w12;
        refract_dir(-wi, no, u_eta, w12);
        vec3 acc = vec3(0.0);
        for (int k = 0; k < u_n_rad; ++k) {
            float r = u_rho * u_rad_t[k];
            vec3 ring = vec3(0.0);
            for (int j = 0; j < u_n_phi; ++j) {
                float phi = 2.0 * PI * float(j) / float(u_n_phi);
                vec3 xi = xo + r * (cos(phi) * t1 + sin(phi) * t2);
                ring += dirpole_sd(xi, no, w12, xo, no, c);
            }
            acc += u_rad_w[k] * (1.0 - smoothstep(0.0, u_rho, r)) * r * ring * (2.0 * PI / float(u_n_phi));
        }
        sum += u_rho * acc * e;
    }
#else
    vec3 e = vec3(0.0);
    for (int l = 0; l < u_n_lights; ++l) {
        vec3 wi;
        e += irradiance_at(l, xo, no, vis[l], wi);
    }
    if (e != vec3(0.0)) {
        vec3 acc = vec3(0.0);
        for (int k = 0; k < u_n_rad; ++k) {
            float r = u_rho * u_rad_t[k];
            acc += u_rad_w[k] * (1.0 - smoothstep(0.0, u_rho, r)) * rd_dipole(r, c) * (2.0 * PI * r);
        }
        sum += u_rho * acc * e;
    }
    sum /= PI;
#endif
    vec3 wo = normalize(u_cam_pos - xo);
    vec3 sub = sum * fresnel_transmittance(clamp(dot(wo, no), 0.0, 1.0), u_eta);
    imageStore(u_sub, px, vec4(sub, 1.0));
    imageStore(u_full, px, vec4(sub + texelFetch(u_grefl, px, 0).rgb, 1.0));
}
