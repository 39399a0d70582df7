// The two diffusion kernels, mirrors dipole_gl/kernels.py (docs/dipole_rivals.md, Eqs. K1-K7).
// The eta-dependent boundary terms are uniforms set once per render by the host
// (quadratures of sslpv_gl/boundary.py). PI comes from sh.glsl.

uniform float u_A;            // Jensen A(eta) = (1 + F_dr)/(1 - F_dr): the standard dipole's z_v
uniform float u_c_phi;        // C_phi(eta) = (1 - 2 C_1)/4
uniform float u_c_e;          // C_E(eta) = (1 - 3 C_2)/2
uniform float u_c_phi_out;    // C_phi(1/eta): the directional dipole's normalisation
uniform float u_A_dir;        // (1 - C_E)/(2 C_phi): the directional dipole's A

struct Coeffs {
    vec3 alpha;               // alpha' = sigma_s'/sigma_t'
    vec3 D;                   // 1/(3 sigma_t')
    vec3 sigma_tr;            // sqrt(sigma_a/D)
    vec3 z_r;                 // 1/sigma_t'
    vec3 z_v;                 // z_r + 4 A D
    vec3 d_e;                 // 2.131 D/sqrt(alpha')
    vec3 sigma_t;             // unreduced extinction (back-lit offset)
};

Coeffs coeffs_of(vec3 sp, vec3 sa, vec3 st)
{
    Coeffs c;
    vec3 stp = sp + sa;
    c.alpha = sp / stp;
    c.D = 1.0 / (3.0 * stp);
    c.sigma_tr = sqrt(sa / c.D);
    c.z_r = 3.0 * c.D;
    c.z_v = c.z_r + 4.0 * u_A * c.D;
    c.d_e = 2.131 * c.D / sqrt(c.alpha);
    c.sigma_t = st;
    return c;
}

// Eq. K1 (Jensen et al. 2001, Eq. 4): R_d(r).
vec3 rd_dipole(float r, Coeffs c)
{
    vec3 s = c.sigma_tr;
    vec3 dr = sqrt(r * r + c.z_r * c.z_r);
    vec3 dv = sqrt(r * r + c.z_v * c.z_v);
    return c.alpha / (4.0 * PI) * (c.z_r * (s + 1.0 / dr) * exp(-s * dr) / (dr * dr)
                                 + c.z_v * (s + 1.0 / dv) * exp(-s * dv) / (dv * dv));
}

// Eq. K4: one ray source, S'_d(x, w, r); xw = x.w and xn = x.n_o per colour, wn = w.n_o.
vec3 ray_source(vec3 xw, vec3 xn, float wn, vec3 r, Coeffs c)
{
    vec3 sr = c.sigma_tr * r;
    vec3 one = 1.0 + sr;
    vec3 r2 = r * r;
    vec3 t0 = exp(-sr) / (r * r2) / (4.0 * u_c_phi_out * 4.0 * PI * PI);
    vec3 fluence = r2 / c.D + 3.0 * one * xw;
    vec3 flux = 3.0 * c.D * one * wn - (one + 3.0 * c.D * (3.0 * one + sr * sr) / r2 * xw) * xn;
    return t0 * (u_c_phi * fluence - u_c_e * flux);
}

// Eqs. K3-K7 (Frisvad et al. 2014): S_d(x_i, w_12; x_o) without the Fresnel transmittances,
// clamped to >= 0. w12 is the refracted travel direction of the light at x_i.
vec3 dirpole_sd(vec3 xi, vec3 ni, vec3 w12, vec3 xo, vec3 no, Coeffs c)
{
    vec3 x = xo - xi;
    float r2 = dot(x, x);
    float r = sqrt(r2);
    vec3 t = cross(ni, x);
    float tl = length(t);
    vec3 ns = (r2 == 0.0 || tl < 1e-6 * r) ? ni : cross(x / r, t / tl);      // modified tangent plane
    float xw = dot(x, w12);
    float mu0 = -dot(no, w12);
    vec3 cos_beta = -sqrt(vec3(max(r2 - xw * xw, 0.0)) / (r2 + c.d_e * c.d_e));
    vec3 dr2 = mu0 > 0.0 ? r2 + c.D * mu0 * (c.D * mu0 - 2.0 * c.d_e * cos_beta)
                         : r2 + 1.0 / (9.0 * c.sigma_t * c.sigma_t);
    vec3 s_real = ray_source(vec3(xw), vec3(dot(x, no)), dot(w12, no), sqrt(dr2), c);
    vec3 wv = w12 - 2.0 * dot(w12, ns) * ns;
    vec3 off = 2.0 * u_A_dir * c.d_e;
    vec3 xvw, xvn, dv;
    for (int k = 0; k < 3; ++k) {                   // the virtual source sits 2 A d_e away, per colour
        vec3 xv = x - off[k] * ns;
        xvw[k] = dot(xv, wv);
        xvn[k] = dot(xv, no);
        dv[k] = length(xv);
    }
    vec3 s_virt = ray_source(xvw, xvn, dot(wv, no), dv, c);
    return max(s_real - s_virt, vec3(0.0));
}
