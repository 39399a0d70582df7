#version 430
// The per-vertex result on the display (scene) mesh: barycentric weights of the closest
// point of the scattering mesh (dipole_gl/vertex.py; Hao & Varshney 2004, Sec. 4.2's
// reference-point weights). Mirrors dipole_gl/twin.py: display().
layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer B       { vec4 b[]; };
layout(std430, binding = 1) readonly buffer Index   { ivec4 idx[]; };
layout(std430, binding = 2) readonly buffer Weights { vec4 wts[]; };
layout(std430, binding = 3) writeonly buffer Out    { vec4 b_display[]; };

uniform int u_count;

void main()
{
    int d = int(gl_GlobalInvocationID.x);
    if (d >= u_count) return;
    ivec4 k = idx[d];
    vec4 w = wts[d];
    b_display[d] = vec4(w.x * b[k.x].rgb + w.y * b[k.y].rgb + w.z * b[k.z].rgb, 0.0);
}
