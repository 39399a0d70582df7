#version 430
// Pass 3 of Carr, Hall & Hart 2003 (Sec. 4.2.4): the model drawn from the camera with each triangle's
// atlas coordinates (dipole_gl/atlas.py: the corners on three corners of its rectangle).
in vec3 in_pos;
in vec3 in_nrm;
in vec2 in_uv;
in vec4 in_rect;                  // the triangle's rectangle: x0, y0, w, h (texels)

uniform mat4 u_view_proj;

out vec3 v_pos;
out vec3 v_nrm;
out vec2 v_uv;
flat out vec4 v_rect;

void main()
{
    v_pos = in_pos;
    v_nrm = in_nrm;
    v_uv = in_uv;
    v_rect = in_rect;
    gl_Position = u_view_proj * vec4(in_pos, 1.0);
}
