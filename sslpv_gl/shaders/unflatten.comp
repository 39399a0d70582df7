#version 430
// Injection atlas (z slices as N x N tiles of a 2D texture) -> 3D SH grid.
// FORMAT (rgba32f / rgba16f) and LOCAL are #defined by the host. Image units are
// fixed by binding qualifiers (moderngl cannot set image uniforms).

layout(local_size_x = LOCAL, local_size_y = LOCAL, local_size_z = LOCAL) in;

uniform sampler2D u_atlas_r;
uniform sampler2D u_atlas_g;
uniform sampler2D u_atlas_b;
uniform int u_N;
uniform int u_tiles_x;

layout(FORMAT, binding = 0) uniform writeonly image3D u_dst_r;
layout(FORMAT, binding = 1) uniform writeonly image3D u_dst_g;
layout(FORMAT, binding = 2) uniform writeonly image3D u_dst_b;

void main()
{
    ivec3 d = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(d, ivec3(u_N)))) return;
    ivec2 pix = ivec2(d.z % u_tiles_x, d.z / u_tiles_x) * u_N + d.xy;
    imageStore(u_dst_r, d, texelFetch(u_atlas_r, pix, 0));
    imageStore(u_dst_g, d, texelFetch(u_atlas_g, pix, 0));
    imageStore(u_dst_b, d, texelFetch(u_atlas_b, pix, 0));
}
