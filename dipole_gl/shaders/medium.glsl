// The material at an exit point (dipole_gl/medium.py): the voxel holding p - (h/2) n.
uniform sampler3D u_sp;        // sigma_s' = sigma_s (1 - g), rgb
uniform sampler3D u_sa;        // sigma_a
uniform sampler3D u_st;        // sigma_t (unreduced)
uniform vec3 u_bbox_min;
uniform vec3 u_bbox_size;
uniform ivec3 u_res;           // nx, ny, nz

ivec3 voxel_at(vec3 p, vec3 n)
{
    vec3 h = u_bbox_size / vec3(u_res);
    vec3 q = p - 0.5 * h * n;
    return clamp(ivec3(floor((q - u_bbox_min) / u_bbox_size * vec3(u_res))), ivec3(0), u_res - 1);
}

Coeffs coeffs_at(vec3 p, vec3 n)
{
    ivec3 v = voxel_at(p, n);
    return coeffs_of(texelFetch(u_sp, v, 0).rgb, texelFetch(u_sa, v, 0).rgb, texelFetch(u_st, v, 0).rgb);
}
