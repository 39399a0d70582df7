#version 430
// Shading input (Sec. 3.3): the accumulation grid times a per-cell, per-colour radiance
// scale, written to a separate grid so that the accumulation itself is untouched (later
// step snapshots keep adding to it). The scale turns accumulated lattice steps into
// physical radiance (docs/diffusion_mapping.md, Eq. (21)) and carries a calibrated global
// factor (sslpv_gl.calibrated). Run only when some scale differs from 1.
// FORMAT and LOCAL are #defined by the host; image units: dst 0-2.

layout(local_size_x = LOCAL, local_size_y = LOCAL, local_size_z = LOCAL) in;

uniform sampler3D u_acc_r;      // accumulation grid per colour
uniform sampler3D u_acc_g;
uniform sampler3D u_acc_b;
uniform sampler3D u_scale;      // rgb: radiance scale per cell
uniform int   u_N;

layout(FORMAT, binding = 0) uniform writeonly image3D u_dst_r;
layout(FORMAT, binding = 1) uniform writeonly image3D u_dst_g;
layout(FORMAT, binding = 2) uniform writeonly image3D u_dst_b;

void main()
{
    ivec3 d = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(d, ivec3(u_N)))) return;
    vec3 s = texelFetch(u_scale, d, 0).rgb;
    imageStore(u_dst_r, d, s.r * texelFetch(u_acc_r, d, 0));
    imageStore(u_dst_g, d, s.g * texelFetch(u_acc_g, d, 0));
    imageStore(u_dst_b, d, s.b * texelFetch(u_acc_b, d, 0));
}
