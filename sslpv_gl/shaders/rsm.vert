#version 430
// Sec. 3.1: reflective shadow map of one point light (also the shadow map).

in vec3 in_pos;                 // world position
in vec3 in_nrm;                 // outward vertex normal

uniform mat4 u_view_proj;       // light's view-projection, frustum fitted to the bounding sphere

out vec3 v_pos;
out vec3 v_nrm;

void main()
{
    v_pos = in_pos;
    v_nrm = in_nrm;
    gl_Position = u_view_proj * vec4(in_pos, 1.0);
}
