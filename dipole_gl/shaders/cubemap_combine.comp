#version 430
// The thesis draft's Step 3 (Ch. 4.1, "Combination"): per camera pixel (exit point x of the
// G-buffer, normal n),
//   L(x) = T(w_o) sum_f V_f C^f(x_proj^f) / sum_f V_f
// over the six faces; x_proj^f is the face texel holding the orthographic projection of the
// intruded point x' = x - eps_c n (Sec. 4.3.2), and V_f = 1 iff the face sees x': the depth cube's
// z_tex back to a distance along the view, d_f = (far - near)/2 (2 z_tex - 1 + (far + near)/(far - near))
// (Sec. 4.3.3), and d(x') < d_f + eps_b (the thesis's z_world - eps_b < z). No visible face: 0.
// Mirrors dipole_gl/twin_cubemap.py: combine().
layout(local_size_x = 8, local_size_y = 8) in;
#include "sh.glsl"
#include "optics.glsl"

layout(std430, binding = 0) readonly buffer Accum { vec4 accum[]; };

layout(binding = 3) uniform sampler2D u_face_pos;
layout(binding = 4) uniform sampler2D u_face_nrm;   // w = z_tex
layout(binding = 5) uniform sampler2D u_gpos;       // camera G-buffer: xyz, w = coverage
layout(binding = 6) uniform sampler2D u_gnrm;
layout(binding = 7) uniform sampler2D u_grefl;
layout(rgba32f, binding = 0) writeonly uniform image2D u_sub;
layout(rgba32f, binding = 1) writeonly uniform image2D u_full;

uniform int   u_face_size;
uniform ivec2 u_size;
uniform vec3  u_centre;             // the cube's centre (the bounding box's)
uniform float u_half;               // half side of every face's orthographic window
uniform float u_near;
uniform float u_far;
uniform vec3  u_eye[6];
uniform vec3  u_right[6];
uniform vec3  u_up[6];
uniform vec3  u_dir[6];             // view direction of each face
uniform float u_eps_c;              // world (Sec. 4.3.2)
uniform float u_eps_b;              // world (Sec. 4.3.3)
uniform float u_eta;
uniform vec3  u_cam_pos;

void main()
{
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    vec4 g = texelFetch(u_gpos, px, 0);
    if (g.w < 0.5) {
        imageStore(u_sub, px, vec4(0.0));
        imageStore(u_full, px, vec4(0.0));
        return;
    }
    int N = u_face_size;
    vec3 x = g.xyz;
    vec3 n = texelFetch(u_gnrm, px, 0).xyz;
    vec3 xs = x - u_eps_c * n;                                       // Sec. 4.3.2
    vec3 sum = vec3(0.0);
    float count = 0.0;
    for (int f = 0; f < 6; ++f) {
        vec2 uv = vec2(dot(xs - u_centre, u_right[f]), dot(xs - u_centre, u_up[f])) / (2.0 * u_half) + 0.5;
        ivec2 t = ivec2(floor(uv * float(N)));
        if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, ivec2(N)))) continue;
        ivec2 tf = t + ivec2(f * N, 0);
        if (texelFetch(u_face_pos, tf, 0).w < 0.5) continue;
        float z_tex = texelFetch(u_face_nrm, tf, 0).w;
        float d_face = 0.5 * (u_far - u_near) * (2.0 * z_tex - 1.0 + (u_far + u_near) / (u_far - u_near));
        float d_point = dot(xs - u_eye[f], u_dir[f]);
        if (d_point < d_face + u_eps_b) {                            // Sec. 4.3.3
            sum += accum[tf.y * 6 * N + tf.x].rgb;
            count += 1.0;
        }
    }
    vec3 wo = normalize(u_cam_pos - x);
    vec3 sub = count > 0.0 ? sum / count * fresnel_transmittance(clamp(dot(wo, n), 0.0, 1.0), u_eta) : vec3(0.0);
    imageStore(u_sub, px, vec4(sub, 1.0));
    imageStore(u_full, px, vec4(sub + texelFetch(u_grefl, px, 0).rgb, 1.0));
}
