#version 430
// Pass 1 of Carr, Hall & Hart 2003 (Sec. 4.2.2, the radiosity map), second half: the transmitted flux
// E_t a of every atlas texel (irradiance.comp over the texels' surface points, the paper's geometry-image
// variant: "the lighting model and Fresnel computation ... in the fragment shader") written into level 0
// of the atlas texture; the host then MIP-maps it, so that a texel of level l holds the mean of E_t a over
// its 2^l x 2^l block, the face cluster under it. Mirrors dipole_gl/twin_atlas.py: radiosity_map().
layout(local_size_x = 8, local_size_y = 8) in;

layout(std430, binding = 4) readonly buffer Total { vec4 total[]; };   // per texel, summed over lights
layout(rgba32f, binding = 0) writeonly uniform image2D u_atlas;

uniform int u_n;                     // atlas texels per side

void main()
{
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (t.x >= u_n || t.y >= u_n) return;
    imageStore(u_atlas, t, vec4(total[t.y * u_n + t.x].rgb, 0.0));
}
