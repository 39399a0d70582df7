// Direct reflection of every point light off a dielectric boundary: the reflection half of
// Mitsuba's roughdielectric (GGX, optics.glsl), with the shadow-map visibility of shadow.glsl.
// Shared by SSLPV's shading (shade.frag) and the dipole rivals (dipole_gl/shaders).
// Include after optics.glsl and shadow.glsl; MAX_LIGHTS is #defined by the host.

uniform float u_alpha;          // GGX roughness
uniform int   u_n_lights;       // 0 for index-matched: no surface reflection
uniform vec3  u_light_I[MAX_LIGHTS];

vec3 direct_reflection(vec3 p, vec3 n, vec3 wo, float eta)
{
    vec3 refl = vec3(0.0);
    for (int i = 0; i < u_n_lights; ++i) {
        vec3 to_l = u_light_pos[i] - p;
        float d2 = dot(to_l, to_l);
        vec3 wi = to_l * inversesqrt(d2);
        float cos_i = dot(wi, n);
        if (cos_i <= 0.0) continue;
        float f = ggx_reflection(wi, wo, n, u_alpha, eta);
        if (f <= 0.0) continue;
        refl += u_light_I[i] / d2 * (f * cos_i * shadow_visibility(i, p, n));
    }
    return refl;
}
