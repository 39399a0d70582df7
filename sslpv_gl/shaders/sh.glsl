// Two-band real spherical harmonics (Borlum et al. 2011, Sec. 4).
// Coefficient order (c00, c1-1, c10, c11) ~ (1, y, z, x), stored in a vec4
// as (x, y, z, w) = (c00, c1-1, c10, c11). Mirrors sslpv_gl/sh.py.

const float PI     = 3.14159265358979323846;
const float SH_Y00 = 0.28209479177387814;   // 1/sqrt(4 pi)
const float SH_Y1  = 0.48860251190291992;   // sqrt(3/(4 pi))
// Clamped-cosine zonal coefficients (authors' answer): sqrt(pi)/2, sqrt(pi/3)
const vec2  SH_CLAMPED_COSINE = vec2(0.88622692545275801, 1.0233267079464885);

// SH projection of max(0, d . w) for unit d (Eq. 1's lobe, rotated to d).
vec4 sh_clamped_cosine(vec3 d)
{
    return vec4(SH_CLAMPED_COSINE.x, SH_CLAMPED_COSINE.y * d.y,
                SH_CLAMPED_COSINE.y * d.z, SH_CLAMPED_COSINE.y * d.x);
}

// c10 in the frame whose z axis is n (Eq. 6, explicit rotation of Sec. 4).
float sh_c10_normal(vec4 c, vec3 n)
{
    return n.y * c.y + n.z * c.z + n.x * c.w;
}

// Area-light radiance towards n of a cell's point light (Eq. 5/7, two bands):
// (2/A) (c00/sqrt(4 pi) + 1/2 sqrt(3/(4 pi)) c10^(n)), without Fresnel T.
float sh_hemisphere_radiance(vec4 c, vec3 n, float area)
{
    return (2.0 / area) * (SH_Y00 * c.x + 0.5 * SH_Y1 * sh_c10_normal(c, n));
}
