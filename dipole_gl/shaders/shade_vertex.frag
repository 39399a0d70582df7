#version 430
// The vertex gather's pixels: L = T(eta, w_o) B (the exit Fresnel transmittance per pixel),
// plus the direct reflection off a dielectric boundary as in gbuffer.frag.
#include "sh.glsl"
#include "optics.glsl"
#include "shadow.glsl"
#include "reflection.glsl"

in vec3 v_pos;
in vec3 v_nrm;
in vec3 v_b;

uniform float u_eta;
uniform vec3  u_cam_pos;

layout(location = 0) out vec4 out_full;
layout(location = 1) out vec4 out_sub;

void main()
{
    vec3 n = normalize(v_nrm);
    vec3 wo = normalize(u_cam_pos - v_pos);
    vec3 sub = v_b * fresnel_transmittance(clamp(dot(wo, n), 0.0, 1.0), u_eta);
    vec3 refl = direct_reflection(v_pos, n, wo, u_eta);
    out_full = vec4(sub + refl, 1.0);
    out_sub = vec4(sub, 1.0);
}
