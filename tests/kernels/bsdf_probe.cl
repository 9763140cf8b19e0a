// Test-only kernels around clrt/kernels/bsdf.cl and sampling.cl, for
// tests/test_bsdf.py: each work-item calls one function on its own inputs and
// writes what came back.  The test expands the include below with clrt's own
// program builder (clrt.device.program.expand_source).
//
// Inputs are float arrays so that the host needs no struct layout: a material
// row is 12 floats (base_color rgb, metallic, alpha, specular_color rgb,
// specular_weight, transmission, ior, 0); n, ng, wo, wi and u are float4
// rows.  With `shared` = 1 every work-item reads row 0 of the material and of
// n, ng and wo (one shading point sampled many times), else row i.
#include "bsdf.cl"

inline Bsdf probe_material(__global const float* m)
{
    Bsdf b;
    b.base_color = (float3)(m[0], m[1], m[2]);
    b.metallic = m[3];
    b.alpha = m[4];
    b.specular_color = (float3)(m[5], m[6], m[7]);
    b.specular_weight = m[8];
    b.transmission = m[9];
    b.ior = m[10];
    return b;
}

__kernel void probe_eval(__global const float* materials, __global const float4* n, __global const float4* ng,
                         __global const float4* wo, __global const float4* wi, const int shared,
                         __global float4* out)
{
    const uint i = get_global_id(0), k = shared ? 0 : i;
    const Bsdf b = probe_material(materials + 12 * k);
    const float3 f = bsdf_eval(&b, n[k].xyz, ng[k].xyz, wo[k].xyz, wi[i].xyz);
    out[i] = (float4)(f, bsdf_pdf(&b, n[k].xyz, ng[k].xyz, wo[k].xyz, wi[i].xyz));
}

// wi_pdf: (wi, pdf); weight_flag: (weight, 0 no sample / 1 sampled / 2 delta lobe sampled)
__kernel void probe_sample(__global const float* materials, __global const float4* n, __global const float4* ng,
                           __global const float4* wo, __global const float4* u, const int shared,
                           __global float4* wi_pdf, __global float4* weight_flag)
{
    const uint i = get_global_id(0), k = shared ? 0 : i;
    const Bsdf b = probe_material(materials + 12 * k);
    BsdfSample s;
    if (bsdf_sample(&b, n[k].xyz, ng[k].xyz, wo[k].xyz, u[i].xyz, &s)) {
        wi_pdf[i] = (float4)(s.wi, s.pdf);
        weight_flag[i] = (float4)(s.weight, s.delta ? 2.0f : 1.0f);
    } else {
        wi_pdf[i] = (float4)(0.0f);
        weight_flag[i] = (float4)(0.0f);
    }
}

// The warps of sampling.cl: 0 cosine hemisphere, 1 uniform hemisphere, 2
// uniform sphere, 3 GGX visible normals for wo = param.xyz, alpha = param.w.
// out: (direction, its pdf as the warp's pdf function gives it).
__kernel void probe_warp(const int which, const float4 param, __global const float4* u, __global float4* out)
{
    const uint i = get_global_id(0);
    const float2 v = u[i].xy;
    float3 d;
    float pdf;
    if (which == 0) {
        d = square_to_cosine_hemisphere(v);
        pdf = cosine_hemisphere_pdf(d);
    } else if (which == 1) {
        d = square_to_uniform_hemisphere(v);
        pdf = uniform_hemisphere_pdf(d);
    } else if (which == 2) {
        d = square_to_uniform_sphere(v);
        pdf = uniform_sphere_pdf();
    } else {
        d = ggx_sample_visible_normal(param.xyz, param.w, v);
        pdf = ggx_visible_normal_pdf(param.xyz, d, param.w);
    }
    out[i] = (float4)(d, pdf);
}

// The densities of probe_warp at given directions.
__kernel void probe_warp_pdf(const int which, const float4 param, __global const float4* d, __global float* out)
{
    const uint i = get_global_id(0);
    const float3 v = d[i].xyz;
    out[i] = which == 0 ? cosine_hemisphere_pdf(v)
           : which == 1 ? uniform_hemisphere_pdf(v)
           : which == 2 ? uniform_sphere_pdf()
           : ggx_visible_normal_pdf(param.xyz, v, param.w);
}

// frame_from_normal's three axes for each n.
__kernel void probe_frame(__global const float4* n, __global float4* out)
{
    const uint i = get_global_id(0);
    const Frame f = frame_from_normal(n[i].xyz);
    out[3 * i] = (float4)(f.t, 0.0f);
    out[3 * i + 1] = (float4)(f.b, 0.0f);
    out[3 * i + 2] = (float4)(f.n, 0.0f);
}

__kernel void probe_constants(__global float* out)
{
    out[0] = BSDF_DELTA_ALPHA;
}
