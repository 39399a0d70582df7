#version 430
// Sec. 3.3: rasterise the mesh from the camera.

in vec3 in_pos;
in vec3 in_nrm;

uniform mat4 u_view_proj;       // camera (conventions' look-at / perspective)

out vec3 v_pos;
out vec3 v_nrm;

void main()
{
    v_pos = in_pos;
    v_nrm = in_nrm;
    gl_Position = u_view_proj * vec4(in_pos, 1.0);
}
