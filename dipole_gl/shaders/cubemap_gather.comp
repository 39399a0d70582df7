#version 430
// The thesis draft's Step 2 gather (Ch. 4.1, Figs. 4.3-4.4, its equation for C^f): per covered
// cube-face texel (exit point x_o, normal n_o) and light,
//   x'_o = x_o - eps_g (n_o - w_l (w_l . n_o))                   (Sec. 4.3.1, the G-buffer fix)
//   uv_c = the light buffer's texel of x'_o (world-to-texture matrix u_light_vp); x_o^T the point
//          the light sees there (the closest point to the light), whose depth sets the disc's size
//   C^f(x_o) += sum_{j in this chunk} L_j S(x_j, x_o) (n_j . w_j) F_t(n_j, w_j) dA_j
// over k samples of an equal-area disc of world radius u_disc_radius (the Vogel spiral, rotated by
// this frame's angle u_phi), each fetched from the light buffer (nearest texel). L_j (n_j . w_j) =
// I cos_j / d_j^2 is the point light's irradiance; every sample covers the same area of the light
// buffer (the thesis's equal-area assumption, taken in the buffer), whose surface area is
// dA_j = dOmega_j d_j^2 / cos_j with dOmega_j = (pi r_uv^2 / k) (2 tan_half)^2 cos^3(theta_j).
// dipole: S = R_d(|x_o - x_j|)/pi; dirpole: S = S_d(x_j, w_12; x_o) (kernels.glsl), the material
// at x_o (medium.glsl). The exit Fresnel is applied in the combination (cubemap_combine.comp).
// Samples u_first .. u_end - 1 per dispatch (dipole_gl/budget.py), added times u_weight (1/frames)
// into Accum. KERNEL_DIRPOLE and MAX_LIGHTS are #defined by the host.
// Mirrors dipole_gl/twin_cubemap.py: gather().
layout(local_size_x = 8, local_size_y = 8) in;
#include "sh.glsl"
#include "optics.glsl"
#include "kernels.glsl"
#include "medium.glsl"

layout(std430, binding = 0) buffer Accum { vec4 accum[]; };   // per face texel: C^f, summed over frames

layout(binding = 3) uniform sampler2D u_face_pos;   // the six faces side by side: xyz, w = covered
layout(binding = 4) uniform sampler2D u_face_nrm;   // xyz, w = z_tex
layout(binding = 5) uniform sampler2D u_lb_pos;     // light buffers side by side: xyz, w = covered
layout(binding = 6) uniform sampler2D u_lb_nrm;

uniform int   u_face_size;          // N: texels per face side
uniform int   u_lb_size;            // light-buffer texels per side
uniform int   u_n_lights;
uniform int   u_samples;            // k
uniform int   u_first;              // this dispatch's disc samples: u_first .. u_end - 1
uniform int   u_end;
uniform float u_phi;                // this frame's disc rotation
uniform float u_weight;             // 1 / frames
uniform float u_disc_radius;        // world radius of the disc at the depth of x_o^T
uniform float u_eps_g;              // in light-buffer texels at x_o's depth (Sec. 4.3.1)
uniform float u_eta;
uniform vec3  u_light_pos[MAX_LIGHTS];
uniform vec3  u_light_I[MAX_LIGHTS];
uniform mat4  u_light_vp[MAX_LIGHTS];   // world -> clip of each light's buffer
uniform vec3  u_light_axis[MAX_LIGHTS]; // each light's unit view axis
uniform float u_tan_half[MAX_LIGHTS];

const float GOLDEN_ANGLE = 2.39996322972865332;     // pi (3 - sqrt 5): the Vogel spiral

void main()
{
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    int N = u_face_size;
    if (px.x >= 6 * N || px.y >= N) return;
    vec4 p = texelFetch(u_face_pos, px, 0);
    if (p.w < 0.5) return;
    vec3 xo = p.xyz;
    vec3 no = texelFetch(u_face_nrm, px, 0).xyz;
    Coeffs c = coeffs_at(xo, no);
    float area_unit = PI / float(u_samples);          // each sample's share of the unit disc
    vec3 sum = vec3(0.0);
    for (int l = 0; l < u_n_lights; ++l) {
        vec3 wl = normalize(u_light_pos[l] - xo);
        float texel = 2.0 * u_tan_half[l] / float(u_lb_size);             // texel size at distance 1
        float eps_g = u_eps_g * texel * dot(xo - u_light_pos[l], u_light_axis[l]);
        vec3 xs = xo - eps_g * (no - wl * dot(wl, no));                   // Sec. 4.3.1
        vec4 clip = u_light_vp[l] * vec4(xs, 1.0);
        vec2 uv = clip.xy / clip.w * 0.5 + 0.5;
        ivec2 tc = ivec2(floor(uv * float(u_lb_size)));
        float depth = dot(xo - u_light_pos[l], u_light_axis[l]);
        if (all(greaterThanEqual(tc, ivec2(0))) && all(lessThan(tc, ivec2(u_lb_size)))) {
            vec4 xt = texelFetch(u_lb_pos, tc + ivec2(l * u_lb_size, 0), 0);
            if (xt.w > 0.5) depth = dot(xt.xyz - u_light_pos[l], u_light_axis[l]);   // x_o^T
        }
        float r_uv = u_disc_radius / (2.0 * u_tan_half[l] * depth);
        float plane = area_unit * r_uv * r_uv * 4.0 * u_tan_half[l] * u_tan_half[l];
        for (int j = u_first; j < u_end; ++j) {
            float rad = sqrt((float(j) + 0.5) / float(u_samples));
            float ang = float(j) * GOLDEN_ANGLE + u_phi;
            vec2 uj = uv + r_uv * rad * vec2(cos(ang), sin(ang));
            if (any(lessThan(uj, vec2(0.0))) || any(greaterThanEqual(uj, vec2(1.0)))) continue;
            ivec2 tj = ivec2(floor(uj * float(u_lb_size))) + ivec2(l * u_lb_size, 0);
            vec4 s = texelFetch(u_lb_pos, tj, 0);
            if (s.w < 0.5) continue;
            vec3 xi = s.xyz;
            vec3 ni = texelFetch(u_lb_nrm, tj, 0).xyz;
            vec3 to_l = u_light_pos[l] - xi;
            float d2 = dot(to_l, to_l);
            vec3 wi = to_l * inversesqrt(d2);
            float cos_i = dot(wi, ni);
            if (cos_i <= 0.0) continue;
            vec2 q = (uj * 2.0 - 1.0) * u_tan_half[l];                   // on the plane at distance 1
            float ct = inversesqrt(1.0 + dot(q, q));
            float dA = plane * ct * ct * ct * d2 / cos_i;                 // surface area of the sample
            vec3 e = u_light_I[l] * (cos_i / d2) * fresnel_transmittance(cos_i, u_eta) * dA;
#if KERNEL_DIRPOLE
            vec3 w12;
            refract_dir(-wi, ni, u_eta, w12);
            sum += dirpole_sd(xi, ni, w12, xo, no, c) * e;
#else
            sum += rd_dipole(length(xo - xi), c) / PI * e;
#endif
        }
    }
    int idx = px.y * 6 * N + px.x;
    accum[idx] += vec4(sum * u_weight, 0.0);
}
