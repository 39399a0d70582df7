#version 430
// G-buffer of the dense gather: the camera's exit points (position, normal), the shadow-map
// visibility of each light there (the gather's near field needs the irradiance at x_o), and the
// direct reflection of each light off a dielectric boundary (GGX, shadow-mapped; the same
// reflection SSLPV's shading adds, sslpv_gl/shaders/shade.frag). MAX_LIGHTS (<= 8) is #defined.
#include "sh.glsl"
#include "optics.glsl"
#include "shadow.glsl"
#include "reflection.glsl"

in vec3 v_pos;
in vec3 v_nrm;

uniform float u_eta;
uniform vec3  u_cam_pos;

layout(location = 0) out vec4 out_pos;      // xyz, w = coverage
layout(location = 1) out vec4 out_nrm;
layout(location = 2) out vec4 out_refl;     // rgb direct reflection
layout(location = 3) out vec4 out_vis0;     // visibility of lights 0-3
layout(location = 4) out vec4 out_vis1;     // visibility of lights 4-7
uniform int u_count_lights;                 // every light (u_n_lights is 0 when index-matched)

void main()
{
    vec3 n = normalize(v_nrm);
    vec3 wo = normalize(u_cam_pos - v_pos);
    vec3 refl = direct_reflection(v_pos, n, wo, u_eta);
    out_pos = vec4(v_pos, 1.0);
    out_nrm = vec4(n, 0.0);
    out_refl = vec4(refl, 1.0);
    float vis[8];
    for (int i = 0; i < 8; ++i)
        vis[i] = i < u_count_lights ? shadow_visibility(i, v_pos, n) : 0.0;
    out_vis0 = vec4(vis[0], vis[1], vis[2], vis[3]);
    out_vis1 = vec4(vis[4], vis[5], vis[6], vis[7]);
}
