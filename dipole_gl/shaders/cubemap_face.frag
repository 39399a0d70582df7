#version 430
// The thesis draft's Step 2 raster (Ch. 4.1, "Render to cubemap"): one orthographic face of the
// cube centred on the object's bounding box sees the object's exit points x_o. Per texel: world
// position (w = covered), normal, and the window depth z_tex = gl_FragCoord.z, which the
// combination step turns back into a distance along the face's view (Sec. 4.3.3). The vertex
// stage is SSLPV's rsm.vert (world position and normal through u_view_proj).

in vec3 v_pos;
in vec3 v_nrm;

layout(location = 0) out vec4 out_pos;    // xyz, w = 1: the texel covers the object
layout(location = 1) out vec4 out_nrm;    // xyz unit outward normal, w = z_tex (the depth cube)

void main()
{
    out_pos = vec4(v_pos, 1.0);
    out_nrm = vec4(normalize(v_nrm), gl_FragCoord.z);
}
