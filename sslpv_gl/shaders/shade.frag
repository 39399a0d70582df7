#version 430
// Sec. 3.3, Eqs. 4-7 (two-band form of Sec. 4):
//   L_o = T (2/A) (c00/sqrt(4 pi) + 1/2 sqrt(3/(4 pi)) c10^(n)),  A = dx^2,
// with c read at x_o - u_shade_shift n (sslpv_gl.shade Eq. (S1); 0 = the paper: x_o's own cell),
// optionally divided by eta^2 (params.eta2; not in the paper's Eq. 4),
//   c10^(n) = n_y c1-1 + n_z c10 + n_x c11,
// plus, for a dielectric boundary, GGX rough-dielectric reflection of each
// point light with shadow-map visibility (Mitsuba's roughdielectric, reflection half).
// LOOKUP_TRILINEAR and MAX_LIGHTS are #defined by the host.
#include "sh.glsl"
#include "optics.glsl"
#include "shadow.glsl"
#include "reflection.glsl"

in vec3 v_pos;
in vec3 v_nrm;

uniform sampler3D u_acc_r;      // accumulation grid per colour
uniform sampler3D u_acc_g;
uniform sampler3D u_acc_b;
uniform vec3  u_bbox_min;
uniform vec3  u_bbox_size;
uniform int   u_N;
uniform float u_area;           // A = dx^2 (Eq. 5)
uniform float u_eta;            // 1 = index-matched (null boundary)
uniform float u_sub_scale;      // 1, or 1/eta^2 with params.eta2 (radiance leaving a medium; not in Eq. 4)
uniform vec3  u_cam_pos;
uniform float u_shade_shift;   // params.shade_depth * dx, scene units (Eq. (S1))

layout(location = 0) out vec4 out_full;      // rgb, a = coverage
layout(location = 1) out vec4 out_sub;       // rgb, a = coverage
layout(location = 2) out vec4 out_pos;       // debug: world position
layout(location = 3) out vec4 out_nrm;       // debug: normal used

vec4 grid_lookup(sampler3D g, vec3 p)
{
#if LOOKUP_TRILINEAR
    return texture(g, (p - u_bbox_min) / u_bbox_size);          // voxel-centre convention, clamp to edge
#else
    ivec3 cell = clamp(ivec3(floor((p - u_bbox_min) / u_bbox_size * float(u_N))), ivec3(0), ivec3(u_N - 1));
    return texelFetch(g, cell, 0);
#endif
}

void main()
{
    vec3 n = normalize(v_nrm);
    vec3 wo = normalize(u_cam_pos - v_pos);          // towards the camera

    // ---- subsurface: Eq. 4 with the area-light estimate (Eqs. 5-7)
    vec3 q = v_pos - u_shade_shift * n;              // where the grid is read (Eq. (S1))
    float T = u_eta == 1.0 ? 1.0 : fresnel_transmittance(clamp(dot(wo, n), 0.0, 1.0), u_eta) * u_sub_scale;
    vec3 sub = T * vec3(sh_hemisphere_radiance(grid_lookup(u_acc_r, q), n, u_area),
                        sh_hemisphere_radiance(grid_lookup(u_acc_g, q), n, u_area),
                        sh_hemisphere_radiance(grid_lookup(u_acc_b, q), n, u_area));

    // ---- direct reflection off a dielectric boundary (none when index-matched)
    vec3 refl = direct_reflection(v_pos, n, wo, u_eta);

    out_full = vec4(sub + refl, 1.0);
    out_sub  = vec4(sub, 1.0);
    out_pos  = vec4(v_pos, 1.0);
    out_nrm  = vec4(n, 1.0);
}
