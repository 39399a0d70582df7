#version 430
// Pass 2 of Carr, Hall & Hart 2003 (Sec. 4.2.3, the scattered irradiance map): per atlas texel b, its
// links (u, v, level, G) into the MIP-mapped radiosity map (dipole_gl/links.py), Eq. (9):
//   B_b = sum_k G_k texelFetch(radiosity, (u_k, v_k), level_k)
// The links run in chunks, one dispatch each (links u_first .. u_end - 1 of every texel), so that no
// invocation exceeds the loop budget of dipole_gl/budget.py (llvmpipe ends an invocation's loops after
// 65,535 iterations in all, silently); the partial sums accumulate per texel in Accum and the last
// dispatch (u_last = 1) writes the scattered irradiance map. Mirrors dipole_gl/twin_atlas.py: gather().
layout(local_size_x = 8, local_size_y = 8) in;

layout(std430, binding = 0) readonly buffer Nodes { int node[]; };     // [texel * slots + k]: level<<24 | v<<12 | u
layout(std430, binding = 1) readonly buffer Factors { vec4 g[]; };     // G per colour
layout(std430, binding = 2) buffer Accum { vec4 accum[]; };            // per texel: the sum so far

layout(binding = 0) uniform sampler2D u_radiosity;                     // pass 1, MIP-mapped
layout(rgba32f, binding = 0) writeonly uniform image2D u_scatter;

uniform int u_n;                     // atlas texels per side
uniform int u_slots;                 // link slots per texel
uniform int u_first;                 // this dispatch's links: u_first .. u_end - 1
uniform int u_end;
uniform int u_last;

void main()
{
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (t.x >= u_n || t.y >= u_n) return;
    int b = t.y * u_n + t.x;
    vec3 sum = u_first == 0 ? vec3(0.0) : accum[b].rgb;
    for (int k = u_first; k < u_end; ++k) {
        int c = node[b * u_slots + k];
        if (c < 0) continue;                                   // an empty slot
        ivec2 uv = ivec2(c & 0xFFF, (c >> 12) & 0xFFF);
        sum += g[b * u_slots + k].rgb * texelFetch(u_radiosity, uv, c >> 24).rgb;
    }
    if (u_last == 0) {
        accum[b] = vec4(sum, 0.0);
        return;
    }
    imageStore(u_scatter, t, vec4(sum, 1.0));
}
