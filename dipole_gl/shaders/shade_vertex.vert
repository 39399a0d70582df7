#version 430
// The vertex gather's raster pass: the display mesh with its per-vertex result B (Gouraud,
// Hao & Varshney 2004, Sec. 3.2).
in vec3 in_pos;
in vec3 in_nrm;
in vec4 in_b;

uniform mat4 u_view_proj;

out vec3 v_pos;
out vec3 v_nrm;
out vec3 v_b;

void main()
{
    v_pos = in_pos;
    v_nrm = in_nrm;
    v_b = in_b.rgb;
    gl_Position = u_view_proj * vec4(in_pos, 1.0);
}
