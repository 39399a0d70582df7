#version 430
// Sec. 3.1: all texels of a cell sum to one point light at its centre
// (additive blending ONE, ONE into three RGBA32F attachments, one per colour).

flat in vec4 v_r;
flat in vec4 v_g;
flat in vec4 v_b;

layout(location = 0) out vec4 out_r;
layout(location = 1) out vec4 out_g;
layout(location = 2) out vec4 out_b;

void main()
{
    out_r = v_r;
    out_g = v_g;
    out_b = v_b;
}
