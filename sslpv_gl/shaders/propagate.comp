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
// ACCUMULATE: 0 = propagate only (steps <= skip), 1 = first accumulated step
// (accum = result), 2 = later steps (accum += result). FORMAT and LOCAL are
// #defined by the host. Image units are fixed by binding qualifiers
// (dst 0-2, accum 3-5; moderngl cannot set image uniforms).

layout(local_size_x = LOCAL, local_size_y = LOCAL, local_size_z = LOCAL) in;

uniform sampler3D u_src_r;      // propagation grid, previous step
uniform sampler3D u_src_g;
uniform sampler3D u_src_b;
uniform sampler3D u_half;       // h = exp(-1/2 sigma_lpv dx) per cell, rgb: half a cell of absorption (destination)
uniform sampler3D u_hk1;        // h * k1 * emit, k1 = (1 - sp) + sp g (Eq. 3 band-1 factor), rgb (source)
uniform sampler3D u_h0;         // h * emit, rgb (source, band 0)
uniform mat4  u_M[6];           // propagation matrices, sources at +x,-x,+y,-y,+z,-z
uniform int   u_N;

layout(FORMAT, binding = 0) uniform writeonly image3D u_dst_r;
layout(FORMAT, binding = 1) uniform writeonly image3D u_dst_g;
layout(FORMAT, binding = 2) uniform writeonly image3D u_dst_b;
#if ACCUMULATE > 0
layout(FORMAT, binding = 3) uniform image3D u_acc_r;
layout(FORMAT, binding = 4) uniform image3D u_acc_g;
layout(FORMAT, binding = 5) uniform image3D u_acc_b;
#endif

const ivec3 OFFSETS[6] = ivec3[6](ivec3(1, 0, 0), ivec3(-1, 0, 0), ivec3(0, 1, 0),
                                  ivec3(0, -1, 0), ivec3(0, 0, 1), ivec3(0, 0, -1));

void main()
{
    ivec3 d = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(d, ivec3(u_N)))) return;

    vec4 out_r = vec4(0.0);                        // gathered coefficients per colour
    vec4 out_g = vec4(0.0);
    vec4 out_b = vec4(0.0);

    for (int s = 0; s < 6; ++s) {
        ivec3 src = d + OFFSETS[s];
        if (any(lessThan(src, ivec3(0))) || any(greaterThanEqual(src, ivec3(u_N))))
            continue;                              // outside the grid: nothing
        vec3 h = texelFetch(u_h0, src, 0).rgb;     // source half of the absorption (times emit)
        vec3 hk = texelFetch(u_hk1, src, 0).rgb;   // ... times Eq. 3 of the SOURCE cell
        vec4 cr = texelFetch(u_src_r, src, 0);
        vec4 cg = texelFetch(u_src_g, src, 0);
        vec4 cb = texelFetch(u_src_b, src, 0);
        out_r += u_M[s] * vec4(h.r * cr.x, hk.r * cr.yzw);
        out_g += u_M[s] * vec4(h.g * cg.x, hk.g * cg.yzw);
        out_b += u_M[s] * vec4(h.b * cb.x, hk.b * cb.yzw);
    }
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
