// Dielectric surface optics, mirrors sslpv_gl/optics.py.
// eta = n_inside / n_outside; normals point outward; cos_i > 0 means light
// arrives from outside (Mitsuba's fresnel() convention).

// Unpolarised Fresnel reflectance (R_s + R_p)/2; 1 on TIR, 0 when eta == 1.
float fresnel_reflectance(float cos_i, float eta)
{
    if (eta == 1.0) return 0.0;                      // index-matched (null BSDF)
    float eta_it = cos_i >= 0.0 ? eta : 1.0 / eta;   // n_t / n_i
    float ci = min(abs(cos_i), 1.0);
    if (ci == 0.0) return 1.0;                       // grazing
    float cos_t2 = 1.0 - (1.0 - ci * ci) / (eta_it * eta_it);
    if (cos_t2 <= 0.0) return 1.0;                   // total internal reflection
    float ct = sqrt(cos_t2);
    float a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    float a_p = (eta_it * ci - ct) / (eta_it * ci + ct);
    return 0.5 * (a_s * a_s + a_p * a_p);
}

float fresnel_transmittance(float cos_i, float eta)
{
    return 1.0 - fresnel_reflectance(cos_i, eta);
}

// Snell refraction of the travelling direction d (unit, towards the surface)
// at the outward unit normal n. Returns false on total internal reflection.
bool refract_dir(vec3 d, vec3 n, float eta, out vec3 t)
{
    float cos_i = -dot(d, n);
    bool outside = cos_i >= 0.0;
    vec3 n_eff = outside ? n : -n;
    float rel = outside ? 1.0 / eta : eta;           // n_incident / n_transmitted
    cos_i = abs(cos_i);
    float sin2_t = rel * rel * (1.0 - cos_i * cos_i);
    if (sin2_t > 1.0) { t = d; return false; }
    float cos_t = sqrt(1.0 - sin2_t);
    t = normalize(rel * d + (rel * cos_i - cos_t) * n_eff);
    return true;
}

// GGX (Walter et al. 2007) reflection half of Mitsuba's roughdielectric:
// D F G / (4 cos_i cos_o), separable Smith G; wi, wo point away from the surface.
float ggx_ndf(float cos_h, float alpha)
{
    if (cos_h <= 0.0) return 0.0;
    float a2 = alpha * alpha;
    float d = cos_h * cos_h * (a2 - 1.0) + 1.0;
    return a2 / (PI * d * d);
}

float smith_g1(float cos_v, float cos_vh, float alpha)
{
    if (cos_vh * cos_v <= 0.0) return 0.0;
    float c2 = clamp(cos_v * cos_v, 1e-30, 1.0);
    float tan2 = (1.0 - c2) / c2;
    return 2.0 / (1.0 + sqrt(1.0 + alpha * alpha * tan2));
}

float ggx_reflection(vec3 wi, vec3 wo, vec3 n, float alpha, float eta)
{
    alpha = max(alpha, 1e-4);
    float cos_i = dot(wi, n);
    float cos_o = dot(wo, n);
    if (cos_i <= 0.0 || cos_o <= 0.0) return 0.0;
    vec3 h = normalize(wi + wo);
    float cos_ih = dot(wi, h);
    float d = ggx_ndf(dot(h, n), alpha);
    float f = fresnel_reflectance(cos_ih, eta);
    float g = smith_g1(cos_i, cos_ih, alpha) * smith_g1(cos_o, dot(wo, h), alpha);
    return d * f * g / (4.0 * cos_i * cos_o);
}
