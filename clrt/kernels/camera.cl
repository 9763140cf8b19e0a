// Ray generation: one primary ray per pixel of a pinhole camera, through the
// pixel centre.  The ray model is fixed so that every system we compare with
// traces exactly the same rays:
//   sx = (2 (px + 0.5) / W - 1) tan(fov/2) W/H,  sy = (1 - 2 (py + 0.5) / H) tan(fov/2)
//   dir = normalize(forward + sx right + sy up), row py = 0 at the top.
// The host computes forward/right/up and the two scale factors once per frame.
#ifndef CLRT_CAMERA_CL
#define CLRT_CAMERA_CL

#include "layouts.h"

typedef struct {
    float3 eye, forward, right, up;
    float scale_x;     // tan(fov/2) * W/H
    float scale_y;     // tan(fov/2)
    uint width, height;
} Camera;

inline Ray camera_ray(const Camera* cam, uint px, uint py)
{
    const float sx = (2.0f * ((float)px + 0.5f) / (float)cam->width - 1.0f) * cam->scale_x;
    const float sy = (1.0f - 2.0f * ((float)py + 0.5f) / (float)cam->height) * cam->scale_y;
    const float3 d = normalize(cam->forward + sx * cam->right + sy * cam->up);
    Ray r;
    r.origin = (float4)(cam->eye, 0.0f);
    r.dir = (float4)(d, INFINITY);
    return r;
}

#endif
