#version 430
// Pass 3 of Carr, Hall & Hart 2003 (Sec. 4.2.4, Eq. 6): the scattered irradiance map looked up
// bilinearly at the fragment's atlas coordinates (level 0, clamped into its triangle's rectangle), L = T(eta, w_o)/pi B, plus the direct
// reflection off a dielectric boundary as in gbuffer.frag. The fragment's point, normal and atlas
// coordinates are written beside it for the self-check. Mirrors dipole_gl/twin_atlas.py: shade().
#include "sh.glsl"
#include "optics.glsl"
#include "shadow.glsl"
#include "reflection.glsl"

in vec3 v_pos;
in vec3 v_nrm;
in vec2 v_uv;
flat in vec4 v_rect;

layout(binding = 1) uniform sampler2D u_scatter;   // pass 2, bilinear
uniform float u_eta;
uniform vec3  u_cam_pos;

layout(location = 0) out vec4 out_full;
layout(location = 1) out vec4 out_sub;
layout(location = 2) out vec4 out_pos_u;
layout(location = 3) out vec4 out_nrm_v;

void main()
{
    vec3 n = normalize(v_nrm);
    vec3 wo = normalize(u_cam_pos - v_pos);
    // the half-texel gutter: the lookup clamped to the rectangle's texel centres, so that bilinear
    // filtering never reads a texel of another triangle
    vec2 n_tex = vec2(textureSize(u_scatter, 0));
    vec2 uv = clamp(v_uv * n_tex, v_rect.xy + 0.5, v_rect.xy + v_rect.zw - 0.5) / n_tex;
    vec3 b = textureLod(u_scatter, uv, 0.0).rgb;
    vec3 sub = b / PI * fresnel_transmittance(clamp(dot(wo, n), 0.0, 1.0), u_eta);
    vec3 refl = direct_reflection(v_pos, n, wo, u_eta);
    out_full = vec4(sub + refl, 1.0);
    out_sub = vec4(sub, 1.0);
    out_pos_u = vec4(v_pos, uv.x);
    out_nrm_v = vec4(n, uv.y);
}
