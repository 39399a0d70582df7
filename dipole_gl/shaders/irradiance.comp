#version 430
// Per surface point (dense sample or scattering vertex) and light: the flux transmitted into
// the medium, Phi = T(eta, cos) I cos / d^2 V dA (Hao & Varshney 2004, Sec. 3.1's L_i (n.w_i)
// mu_i dA with the Fresnel transmittance; Carr et al. 2003, Sec. 4.2.2's radiosity map), with
// the shadow-map visibility V, and the refracted travel direction w_12 of the light (the
// directional dipole's ray source). Mirrors dipole_gl/twin.py: irradiance().
layout(local_size_x = 64) in;
#include "sh.glsl"
#include "optics.glsl"
#include "shadow.glsl"

layout(std430, binding = 0) readonly buffer Points  { vec4 pos_area[]; };   // xyz, w = area
layout(std430, binding = 1) readonly buffer Normals { vec4 nrm[]; };
layout(std430, binding = 2) writeonly buffer Flux   { vec4 flux[]; };       // [light * S + i]: rgb, a = V
layout(std430, binding = 3) writeonly buffer Dirs   { vec4 w12[]; };        // [light * S + i]: xyz, w = cos
layout(std430, binding = 4) writeonly buffer Total  { vec4 total[]; };      // sum over lights

uniform int u_count;
uniform int u_n_lights;
uniform float u_eta;
uniform vec3 u_light_I[MAX_LIGHTS];

void main()
{
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    vec3 p = pos_area[i].xyz;
    vec3 n = nrm[i].xyz;
    vec3 sum = vec3(0.0);
    for (int l = 0; l < u_n_lights; ++l) {
        vec3 to_l = u_light_pos[l] - p;
        float d2 = dot(to_l, to_l);
        vec3 wi = to_l * inversesqrt(d2);
        float cos_i = dot(wi, n);
        vec4 f = vec4(0.0);
        vec3 t = -n;
        if (cos_i > 0.0) {
            float vis = shadow_visibility(l, p, n);
            f = vec4(u_light_I[l] * (cos_i * fresnel_transmittance(cos_i, u_eta) * vis / d2 * pos_area[i].w), vis);
            refract_dir(-wi, n, u_eta, t);
        }
        flux[l * u_count + i] = f;
        w12[l * u_count + i] = vec4(t, cos_i);
        sum += f.rgb;
    }
    total[i] = vec4(sum, 0.0);
}
