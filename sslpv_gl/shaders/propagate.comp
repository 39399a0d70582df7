#version 430
// Sec. 3.2 and Sec. 4: one propagation step, gathering from the six axial
// neighbours (conventions' transfer rule):
//   c_d += M_s (exp(-1/2 (sigma[s] + sigma[d]) dx) S(s) c_s),
//   S(s) = diag(1, k1, k1, k1), k1 = (1 - sp[s]) + sp[s] g[s]     (Eq. 3, SOURCE cell)
// Absorption (Sec. 3.2.1) is separable: exp(-1/2 (sigma_s + sigma_d) dx) = h_s h_d with
// h = exp(-1/2 sigma dx) per cell, formed once on the host. So the gather needs no exp,
// and h_d multiplies the whole sum once. A sink cell (emit = 0: outside = absorb or
// extrapolated, sslpv_gl.boundary) keeps what it receives but sends nothing on, so the
// SOURCE factors carry emit (u_h0 = h emit, u_hk1 = h k1 emit) and the destination's h does not.
// outside = interior (issue 28): the alpha of u_h0 and u_half is 1 in empty cells, and the
// transfer between two empty cells is cut, link = 1 - e_s e_d (twin.propagate's `empty`).
// Every other mode has alpha 0, so link = 1 exactly and the step is bit-identical.
// boundary_reflect = rdr (sslpv_gl.reflect, Eq. R3): the alpha of u_hk1 is 1 in inside cells, and
// u_R = R_dr(eta). A transfer from an inside to an outside cell keeps 1 - u_R; an inside cell whose
// neighbour at off is outside (or beyond the grid) receives u_R h_d^2 M_s F c_d, the lobe mirrored
// about the face (F: the band-1 coefficient along the face's axis negated), as from its mirror
// image at d + off. u_R = 0 (the paper, or eta = 1) leaves the step bit-identical.
// The dispatch covers the cells u_lo..u_hi (inclusive), the source grid's non-zero support
// dilated by one cell per step (sslpv_gl.propagate.region): light moves at most one cell per
// step, so every cell beyond holds exactly 0, as the host cleared it (issue 14).
// ACCUMULATE: 0 = propagate only (steps <= skip), 1 = first accumulated step
// (accum = result), 2 = later steps (accum += result). FORMAT and LOCAL are
// #defined by the host. Image units are fixed by binding qualifiers
// (dst 0-2, accum 3-5; moderngl cannot set image uniforms).

layout(local_size_x = LOCAL, local_size_y = LOCAL, local_size_z = LOCAL) in;

uniform sampler3D u_src_r;      // propagation grid, previous step
uniform sampler3D u_src_g;
uniform sampler3D u_src_b;
uniform sampler3D u_half;       // h = exp(-1/2 sigma_lpv dx) per cell, rgb: half a cell of absorption (destination); a: empty
uniform sampler3D u_hk1;        // h * k1 * emit, k1 = (1 - sp) + sp g (Eq. 3 band-1 factor), rgb (source); a: inside
uniform sampler3D u_h0;         // h * emit, rgb (source, band 0); a: empty
uniform mat4  u_M[6];           // propagation matrices, sources at +x,-x,+y,-y,+z,-z
uniform int   u_N;
uniform float u_R;              // R_dr(eta) of boundary_reflect = rdr; 0 otherwise
uniform ivec3 u_lo;             // first cell of this step's region (x, y, z)
uniform ivec3 u_hi;             // last cell of this step's region, < u_N

layout(FORMAT, binding = 0) uniform writeonly image3D u_dst_r;
layout(FORMAT, binding = 1) uniform writeonly image3D u_dst_g;
layout(FORMAT, binding = 2) uniform writeonly image3D u_dst_b;
#if ACCUMULATE > 0
layout(FORMAT, binding = 3) uniform image3D u_acc_r;
layout(FORMAT, binding = 4) uniform image3D u_acc_g;
layout(FORMAT, binding = 5) uniform image3D u_acc_b;
#endif

// One source cell at d + off (the s-th of SOURCE_OFFSETS). Each axial M_s has six non-zero
// entries (sslpv_gl.sh.axial_pattern, checked on the host when the program is built): band 0
// and the band-1 coefficient along the source's axis (index a) mix, and the two transverse
// band-1 coefficients (t1, t2) only scale. Six products per colour instead of the mat4's
// sixteen: the mat4 products were about 16 % of a step on llvmpipe, and this form about 10 %
// faster in all (issue 14). The result equals M_s * c up to float rounding: the skipped
// entries are 0 by symmetry (|entry| < 1e-12 max|M| in float64, the quadrature's noise).
// M_s applied to one source's scaled coefficients (c0: band 0; ca, c1, c2: band 1 along the axis
// index a and the transverse t1, t2), added to the destination's sums.
void transfer(int s, int a, int t1, int t2, vec3 c0, vec3 ca, vec3 c1, vec3 c2,
              inout vec4 out_r, inout vec4 out_g, inout vec4 out_b)
{
    mat4 M = u_M[s];                               // GLSL M[column][row]
    vec3 o0 = M[0][0] * c0 + M[a][0] * ca;
    vec3 oa = M[0][a] * c0 + M[a][a] * ca;
    vec3 o1 = M[t1][t1] * c1;
    vec3 o2 = M[t2][t2] * c2;
    out_r.x += o0.r;  out_g.x += o0.g;  out_b.x += o0.b;
    out_r[a] += oa.r;  out_g[a] += oa.g;  out_b[a] += oa.b;
    out_r[t1] += o1.r;  out_g[t1] += o1.g;  out_b[t1] += o1.b;
    out_r[t2] += o2.r;  out_g[t2] += o2.g;  out_b[t2] += o2.b;
}

// One source cell at d + off (the s-th of SOURCE_OFFSETS). Each axial M_s has six non-zero
// entries (sslpv_gl.sh.axial_pattern, checked on the host when the program is built): band 0
// and the band-1 coefficient along the source's axis (index a) mix, and the two transverse
// band-1 coefficients (t1, t2) only scale. Six products per colour instead of the mat4's
// sixteen: the mat4 products were about 16 % of a step on llvmpipe, and this form about 10 %
// faster in all (issue 14). The result equals M_s * c up to float rounding: the skipped
// entries are 0 by symmetry (|entry| < 1e-12 max|M| in float64, the quadrature's noise).
// in_d, h_d0, hk_d, cd_*: the destination's inside flag, source factors and coefficients (Eq. R3).
void gather(ivec3 d, ivec3 off, int s, int a, int t1, int t2, float e_d, float in_d, vec3 h_d0, vec3 hk_d,
            vec4 cd_r, vec4 cd_g, vec4 cd_b, inout vec4 out_r, inout vec4 out_g, inout vec4 out_b)
{
    ivec3 src = d + off;
    bool beyond = any(lessThan(src, ivec3(0))) || any(greaterThanEqual(src, ivec3(u_N)));
    vec4 hk4 = beyond ? vec4(0.0) : texelFetch(u_hk1, src, 0);
    if (u_R > 0.0 && in_d > 0.5 && hk4.a < 0.5) {  // a surface face: the mirror image at src (Eq. R3)
        transfer(s, a, t1, t2, u_R * h_d0 * vec3(cd_r.x, cd_g.x, cd_b.x),
                 -u_R * hk_d * vec3(cd_r[a], cd_g[a], cd_b[a]),
                 u_R * hk_d * vec3(cd_r[t1], cd_g[t1], cd_b[t1]),
                 u_R * hk_d * vec3(cd_r[t2], cd_g[t2], cd_b[t2]), out_r, out_g, out_b);
    }
    if (beyond)
        return;                                    // outside the grid: nothing
    vec4 h4 = texelFetch(u_h0, src, 0);
    float link = (1.0 - h4.a * e_d)                // 0 between two empty cells, else exactly 1
               * (1.0 - u_R * hk4.a * (1.0 - in_d));   // 1 - R_dr from an inside to an outside cell
    vec3 h = h4.rgb * link;                        // source half of the absorption (times emit)
    vec3 hk = hk4.rgb * link;                      // ... times Eq. 3 of the SOURCE cell
    vec4 cr = texelFetch(u_src_r, src, 0);
    vec4 cg = texelFetch(u_src_g, src, 0);
    vec4 cb = texelFetch(u_src_b, src, 0);
    transfer(s, a, t1, t2, h * vec3(cr.x, cg.x, cb.x), hk * vec3(cr[a], cg[a], cb[a]),
             hk * vec3(cr[t1], cg[t1], cb[t1]), hk * vec3(cr[t2], cg[t2], cb[t2]), out_r, out_g, out_b);
}

void main()
{
    ivec3 d = u_lo + ivec3(gl_GlobalInvocationID);
    if (any(greaterThan(d, u_hi))) return;

    vec4 out_r = vec4(0.0);                        // gathered coefficients per colour
    vec4 out_g = vec4(0.0);
    vec4 out_b = vec4(0.0);
    float e_d = texelFetch(u_half, d, 0).a;        // 1: the destination is an empty cell
    vec4 hk_d4 = texelFetch(u_hk1, d, 0);          // the destination's own source factors and inside flag,
    float in_d = hk_d4.a;                          // read for the reflection of Eq. R3
    vec3 h_d0 = texelFetch(u_h0, d, 0).rgb;
    vec4 cd_r = vec4(0.0), cd_g = vec4(0.0), cd_b = vec4(0.0);
    if (u_R > 0.0 && in_d > 0.5) {
        cd_r = texelFetch(u_src_r, d, 0);
        cd_g = texelFetch(u_src_g, d, 0);
        cd_b = texelFetch(u_src_b, d, 0);
    }
    // coefficient order (c00, c1-1, c10, c11) ~ (1, y, z, x): the x axis is index 3, y 1, z 2
    gather(d, ivec3(1, 0, 0), 0, 3, 1, 2, e_d, in_d, h_d0, hk_d4.rgb, cd_r, cd_g, cd_b, out_r, out_g, out_b);
    gather(d, ivec3(-1, 0, 0), 1, 3, 1, 2, e_d, in_d, h_d0, hk_d4.rgb, cd_r, cd_g, cd_b, out_r, out_g, out_b);
    gather(d, ivec3(0, 1, 0), 2, 1, 2, 3, e_d, in_d, h_d0, hk_d4.rgb, cd_r, cd_g, cd_b, out_r, out_g, out_b);
    gather(d, ivec3(0, -1, 0), 3, 1, 2, 3, e_d, in_d, h_d0, hk_d4.rgb, cd_r, cd_g, cd_b, out_r, out_g, out_b);
    gather(d, ivec3(0, 0, 1), 4, 2, 1, 3, e_d, in_d, h_d0, hk_d4.rgb, cd_r, cd_g, cd_b, out_r, out_g, out_b);
    gather(d, ivec3(0, 0, -1), 5, 2, 1, 3, e_d, in_d, h_d0, hk_d4.rgb, cd_r, cd_g, cd_b, out_r, out_g, out_b);
    vec3 h_d = texelFetch(u_half, d, 0).rgb;       // destination half of the absorption
    out_r *= h_d.r;
    out_g *= h_d.g;
    out_b *= h_d.b;

    imageStore(u_dst_r, d, out_r);
    imageStore(u_dst_g, d, out_g);
    imageStore(u_dst_b, d, out_b);
#if ACCUMULATE == 1
    imageStore(u_acc_r, d, out_r);
    imageStore(u_acc_g, d, out_g);
    imageStore(u_acc_b, d, out_b);
#elif ACCUMULATE == 2
    imageStore(u_acc_r, d, imageLoad(u_acc_r, d) + out_r);
    imageStore(u_acc_g, d, imageLoad(u_acc_g, d) + out_g);
    imageStore(u_acc_b, d, imageLoad(u_acc_b, d) + out_b);
#endif
}
