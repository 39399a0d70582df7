#version 430
// Single scattering S^(1) (Jensen et al. 2001, Sec. 2.3, Eq. 8 and the estimate of s'_i below it)
// per camera pixel (exit point x_o of the G-buffer), for every point light:
//   L1 = T(w_o)/eta^2 int_0^inf sigma_s p(cos) E'(x) e^(-sigma_t s'_i) e^(-sigma_t s) ds
// along the refracted view ray x = x_o + s d. The light reaches x through the entry point x_i,
// found in the light atlas (position and normal of the first surface point seen from the light,
// bilinear over the valid texels): s_i = |y - x| - |y - x_i|, Jensen's refracted distance
// s'_i = s_i cos_i / cos_t (Snell on the plane of x_i), the refracted travel direction at x_i
// and the irradiance through a flat interface E' = I T(cos_i) (cos_i / cos_t) / spread
// (docs/dipole_rivals.md, Sec. 11). The material is that of the exit point (medium.glsl).
// The march is a midpoint rule in u = 1 - e^(-sigma_ref s), sigma_ref the smallest sigma_t:
// N_MARCH nodes, no truncation. Loops: N_MARCH x lights x 4 atlas taps per invocation
// (dipole_gl/budget.py). Mirrors dipole_gl/single_twin.py: single_scattering().
// MAX_LIGHTS is #defined by the host.
layout(local_size_x = 8, local_size_y = 8) in;
#include "sh.glsl"
#include "optics.glsl"
#include "kernels.glsl"
#include "medium.glsl"

layout(binding = 3) uniform sampler2D u_gpos;       // xyz, w = coverage
layout(binding = 4) uniform sampler2D u_gnrm;
layout(binding = 5) uniform sampler2D u_grefl;      // direct reflection (terms = single)
layout(binding = 6) uniform sampler2D u_atlas_pos;  // light atlas: world position, w = valid; one tile per light
layout(binding = 7) uniform sampler2D u_atlas_nrm;  // ... and the outward normal there
layout(rgba32f, binding = 0) uniform image2D u_sub;
layout(rgba32f, binding = 1) uniform image2D u_full;
layout(rgba32f, binding = 2) writeonly uniform image2D u_single;

uniform int   u_add;                  // 1: add S1 to u_sub/u_full (terms = both); 0: write it (single)
uniform int   u_n_lights;
uniform int   u_n_march;
uniform float u_eta;
uniform vec3  u_cam_pos;
uniform ivec2 u_size;
uniform vec3  u_light_pos[MAX_LIGHTS];
uniform vec3  u_light_I[MAX_LIGHTS];
uniform mat4  u_light_vp[MAX_LIGHTS];
uniform int   u_shadow_size;                    // atlas tile size in texels

// Henyey-Greenstein, per colour; cos_t between the light's and the scattered travel directions.
vec3 hg(float cos_t, vec3 g)
{
    vec3 d = 1.0 + g * g - 2.0 * g * cos_t;
    return (1.0 - g * g) / (4.0 * PI * d * sqrt(d));
}

// The light of light l scattered at x towards x_o (travel direction `back`), before the exit.
vec3 light_term(int l, vec3 x, vec3 back, vec3 ss, vec3 st, vec3 g)
{
    vec3 to_l = u_light_pos[l] - x;
    float dist = length(to_l);
    vec3 wi = to_l / dist;
    vec4 clip = u_light_vp[l] * vec4(x, 1.0);
    if (clip.w <= 0.0) return vec3(0.0);
    vec2 uv = clip.xy / clip.w * 0.5 + 0.5;
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) return vec3(0.0);
    // ---- the entry point: bilinear over the valid texels of the light atlas
    vec2 f = uv * float(u_shadow_size) - 0.5;
    ivec2 i0 = ivec2(floor(f));
    vec2 t = f - vec2(i0);
    float wsum = 0.0, dsum = 0.0;
    vec3 nsum = vec3(0.0);
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 q = clamp(i0 + o, ivec2(0), ivec2(u_shadow_size - 1)) + ivec2(l * u_shadow_size, 0);
        vec4 p = texelFetch(u_atlas_pos, q, 0);
        if (p.w < 0.5) continue;
        float w = (o.x == 1 ? t.x : 1.0 - t.x) * (o.y == 1 ? t.y : 1.0 - t.y);
        wsum += w;
        dsum += w * length(p.xyz - u_light_pos[l]);
        nsum += w * texelFetch(u_atlas_nrm, q, 0).xyz;
    }
    if (wsum <= 0.0 || dot(nsum, nsum) == 0.0) return vec3(0.0);
    float d_i = dsum / wsum;                                  // light -> entry point
    vec3 ni = normalize(nsum);
    float cos_i = dot(wi, ni);
    if (cos_i <= 0.0) return vec3(0.0);
    float s_i = dist - d_i;
    if (s_i < 0.0) return vec3(0.0);                          // x in front of the lit surface: outside
    float eta2 = u_eta * u_eta;
    float cos_t = sqrt(max(1.0 - (1.0 - cos_i * cos_i) / eta2, 0.0));
    float sp_i = s_i * cos_i / cos_t;                         // Jensen's s'_i
    vec3 w12;
    refract_dir(-wi, ni, u_eta, w12);
    // a point light through a flat interface: sagittal and tangential spread of the refracted beam
    float spread = (d_i + sp_i / u_eta) * (d_i + sp_i * cos_i * cos_i / (u_eta * cos_t * cos_t));
    float e = fresnel_transmittance(cos_i, u_eta) * (cos_i / cos_t) / spread;
    return u_light_I[l] * e * ss * hg(dot(w12, back), g) * exp(-st * sp_i);
}

void main()
{
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    vec4 gp = texelFetch(u_gpos, px, 0);
    vec3 s1 = vec3(0.0);
    if (gp.w >= 0.5) {
        vec3 xo = gp.xyz;
        vec3 no = normalize(texelFetch(u_gnrm, px, 0).xyz);
        vec3 wo = normalize(u_cam_pos - xo);
        float mu_o = dot(wo, no);
        if (mu_o > 0.0) {
            vec3 d;
            refract_dir(-wo, no, u_eta, d);                   // the refracted view ray, into the medium
            ivec3 v = voxel_at(xo, no);
            vec3 sp = texelFetch(u_sp, v, 0).rgb;
            vec3 sa = texelFetch(u_sa, v, 0).rgb;
            vec3 st = texelFetch(u_st, v, 0).rgb;
            vec3 ss = st - sa;                                // sigma_s
            vec3 g = 1.0 - sp / ss;                           // sigma_s' = sigma_s (1 - g)
            float sref = min(st.r, min(st.g, st.b));
            vec3 acc = vec3(0.0);
            for (int k = 0; k < u_n_march; ++k) {
                float u = (float(k) + 0.5) / float(u_n_march);
                float s = -log(1.0 - u) / sref;
                vec3 x = xo + s * d;
                vec3 w = exp(-(st - sref) * s) / (float(u_n_march) * sref);   // int e^(-st s) ds
                for (int l = 0; l < u_n_lights; ++l)
                    acc += w * light_term(l, x, -d, ss, st, g);
            }
            s1 = acc * fresnel_transmittance(mu_o, u_eta) / (u_eta * u_eta);
        }
    }
    imageStore(u_single, px, vec4(s1, gp.w >= 0.5 ? 1.0 : 0.0));
    if (u_add == 1) {
        vec4 sub = imageLoad(u_sub, px), full = imageLoad(u_full, px);
        imageStore(u_sub, px, vec4(sub.rgb + s1, sub.a));
        imageStore(u_full, px, vec4(full.rgb + s1, full.a));
    } else {
        float a = gp.w >= 0.5 ? 1.0 : 0.0;
        imageStore(u_sub, px, vec4(s1, a));
        imageStore(u_full, px, vec4(s1 + texelFetch(u_grefl, px, 0).rgb * a, a));
    }
}
