#version 430
// Sec. 3.1: RSM texel = (world position, normal, incoming flux Phi_p).
// Phi_p = I dOmega_p, dOmega_p = A_p cos^3(theta_p) / near^2 with A_p the
// shadow-map plane area at `near` over Nx*Ny (authors' answer, 003_...):
// A_p / near^2 = (2 tan_x)(2 tan_y) / (Nx Ny), independent of `near`.

in vec3 v_pos;
in vec3 v_nrm;

uniform vec3  u_intensity;      // W/sr, RGB
uniform vec2  u_tan_half;       // tan of the half field of view, (x, y)
uniform vec4  u_viewport;       // (x0, y0, width, height) of this light's map, in pixels

layout(location = 0) out vec4 out_pos;    // xyz, w = 1: texel covers the mesh
layout(location = 1) out vec4 out_nrm;    // xyz unit outward normal
layout(location = 2) out vec4 out_flux;   // rgb Phi_p (W)

void main()
{
    vec2 ndc = (gl_FragCoord.xy - u_viewport.xy) / u_viewport.zw * 2.0 - 1.0;   // texel centre
    vec2 uv = ndc * u_tan_half;                     // point on the plane at distance 1
    float cos_theta = inversesqrt(1.0 + dot(uv, uv));
    float d_omega = 4.0 * u_tan_half.x * u_tan_half.y / (u_viewport.z * u_viewport.w)
                  * cos_theta * cos_theta * cos_theta;
    out_pos  = vec4(v_pos, 1.0);
    out_nrm  = vec4(normalize(v_nrm), 0.0);
    out_flux = vec4(u_intensity * d_omega, 0.0);
}
