#version 430
// Sec. 3.1, Eq. 1: one point per RSM texel, written into the flattened grid
// atlas (z slices as N x N tiles) with additive blending.
#include "sh.glsl"
#include "optics.glsl"

uniform sampler2D u_pos;        // RSM: xyz, w = valid
uniform sampler2D u_nrm;        // RSM: outward normal
uniform sampler2D u_flux;       // RSM: Phi_p rgb
uniform int   u_width;          // RSM width (texel id -> (x, y))
uniform vec3  u_light;          // light position
uniform vec3  u_bbox_min;       // LPV grid box
uniform vec3  u_dx;             // cell size per axis
uniform int   u_N;              // grid resolution
uniform float u_eta;            // n_inside / n_outside
uniform float u_offset;         // move the virtual light inwards along -n (0 = paper)
uniform sampler3D u_depth;      // per cell: a further inward move (inject_depth reduced mean free paths)
uniform int   u_depth_on;       // 0: no u_depth bound (the paper, and inject_depth = 0)
uniform int   u_tiles_x;        // atlas tiles per row
uniform vec2  u_atlas_size;     // atlas size in pixels

flat out vec4 v_r;              // SH coefficients per colour
flat out vec4 v_g;
flat out vec4 v_b;

void main()
{
    ivec2 tc = ivec2(gl_VertexID % u_width, gl_VertexID / u_width);
    vec4 p = texelFetch(u_pos, tc, 0);
    gl_PointSize = 1.0;
    v_r = v_g = v_b = vec4(0.0);
    if (p.w < 0.5) {                               // texel misses the mesh: clip it
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        return;
    }
    vec3 n   = normalize(texelFetch(u_nrm, tc, 0).xyz);
    vec3 phi = texelFetch(u_flux, tc, 0).rgb;

    // ---- Eq. 1: refracted clamped-cosine lobe times (1/pi) T Phi_p
    vec3 w_i = normalize(p.xyz - u_light);         // incident, travelling
    vec3 w_t;
    bool ok = refract_dir(w_i, n, u_eta, w_t);
    float T = ok ? fresnel_transmittance(-dot(w_i, n), u_eta) : 0.0;
    vec4 lobe = sh_clamped_cosine(w_t) * (T / PI);
    v_r = lobe * phi.r;
    v_g = lobe * phi.g;
    v_b = lobe * phi.b;

    // ---- the cell containing x_p - offset n (clamped into the grid); the depth is that of x_p's own cell
    float offset = u_offset;
    if (u_depth_on != 0) {
        ivec3 here = clamp(ivec3(floor((p.xyz - u_bbox_min) / u_dx)), ivec3(0), ivec3(u_N - 1));
        offset += texelFetch(u_depth, here, 0).r;
    }
    ivec3 cell = clamp(ivec3(floor((p.xyz - offset * n - u_bbox_min) / u_dx)), ivec3(0), ivec3(u_N - 1));
    ivec2 pix = ivec2(cell.z % u_tiles_x, cell.z / u_tiles_x) * u_N + cell.xy;
    gl_Position = vec4((vec2(pix) + 0.5) / u_atlas_size * 2.0 - 1.0, 0.0, 1.0);
}
