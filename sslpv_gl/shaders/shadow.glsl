// Point-light visibility from the shadow-map atlas of sslpv_gl.rsm.render_shadow_atlas:
// one tile per light holding the world position seen from the light (w = valid).
// Shared by SSLPV's shading (shade.frag) and the dipole rivals' irradiance and shading
// (dipole_gl/shaders). MAX_LIGHTS is #defined by the host.

uniform vec3  u_light_pos[MAX_LIGHTS];
uniform mat4  u_light_vp[MAX_LIGHTS];
uniform sampler2D u_shadow;     // shadow-map atlas: world position (w = valid), one tile per light
uniform int   u_shadow_size;    // tile size in texels
uniform float u_shadow_texel[MAX_LIGHTS];   // world size of a texel at unit distance (2 tan / size)

float shadow_visibility(int i, vec3 p, vec3 n)
{
    vec4 clip = u_light_vp[i] * vec4(p, 1.0);
    vec2 uv = clip.xy / clip.w * 0.5 + 0.5;
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) return 1.0;
    float dist = length(p - u_light_pos[i]);
    vec3 l = (u_light_pos[i] - p) / dist;
    // slope-scaled bias: a few texel footprints, more at grazing light
    float bias = 2.0 * u_shadow_texel[i] * dist / max(dot(n, l), 0.2);
    ivec2 base = ivec2(uv * float(u_shadow_size));
    float vis = 0.0;
    for (int dy = -1; dy <= 1; ++dy)               // 3x3 percentage-closer filter
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 t = clamp(base + ivec2(dx, dy), ivec2(0), ivec2(u_shadow_size - 1));
            vec4 s = texelFetch(u_shadow, t + ivec2(i * u_shadow_size, 0), 0);
            vis += (s.w < 0.5 || dist <= length(s.xyz - u_light_pos[i]) + bias) ? 1.0 : 0.0;
        }
    return vis / 9.0;
}
