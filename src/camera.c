/* Pinhole camera: the basis is computed once here, in double, and rounded to the float push
 * constants both tracers read, so the CPU and the GPU start every ray from identical bits; the
 * CPU double-precision reference reads the same rounded basis as doubles and generates its
 * rays from it in double. */
#include "camera.h"

#include <math.h>

#define DEFAULT_FOV_DEGREES 45.0
/* |sin| of the angle between up and the view direction below which the basis degenerates:
 * cross(forward, up) would be dominated by rounding and the image would spin arbitrarily. */
#define MIN_UP_SIN 1e-6

typedef struct dvec3 { double x, y, z; } dvec3;

static dvec3 dsub(dvec3 a, dvec3 b) { return (dvec3){ a.x - b.x, a.y - b.y, a.z - b.z }; }
static dvec3 dscale(dvec3 a, double s) { return (dvec3){ a.x * s, a.y * s, a.z * s }; }
static double dlength(dvec3 a) { return sqrt(a.x * a.x + a.y * a.y + a.z * a.z); }
static dvec3 dcross(dvec3 a, dvec3 b)
{
    return (dvec3){ a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x };
}
static dvec3 dnormalize(dvec3 a) { return dscale(a, 1.0 / dlength(a)); }
static dvec3 from_floats(const float f[3]) { return (dvec3){ f[0], f[1], f[2] }; }
static vkrt_float3 to_float3(const double a[3]) { return (vkrt_float3){ (float)a[0], (float)a[1], (float)a[2] }; }

static int all_finite(const float f[3])
{
    return isfinite(f[0]) && isfinite(f[1]) && isfinite(f[2]);
}

static dvec3 through_float(dvec3 a) { return (dvec3){ (float)a.x, (float)a.y, (float)a.z }; }

static void to_doubles(dvec3 a, double out[3])
{
    out[0] = a.x, out[1] = a.y, out[2] = a.z;
}

vkrt_result camera_setup_double(core *c, const vkrt_camera *camera, uint32_t width, uint32_t height,
                                camera_basis *out)
{
    if (!camera || !out) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "camera_setup: NULL argument");
    if (width == 0 || height == 0)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "image size %ux%u has a zero side", width, height);
    if (!all_finite(camera->eye))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_camera.eye is not finite");
    if (!all_finite(camera->target))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_camera.target is not finite");
    if (!all_finite(camera->up))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_camera.up is not finite");
    if (!isfinite(camera->fov_y_degrees))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_camera.fov_y_degrees is not finite");

    dvec3 eye = from_floats(camera->eye), target = from_floats(camera->target);
    if (eye.x == target.x && eye.y == target.y && eye.z == target.z) {
        eye = (dvec3){ 0.0, 0.0, CAMERA_DEFAULT_EYE_Z };
        target = (dvec3){ 0.0, 0.0, 0.0 };
    }
    dvec3 up = from_floats(camera->up);
    if (up.x == 0.0 && up.y == 0.0 && up.z == 0.0) up = (dvec3){ 0.0, 1.0, 0.0 };
    double fov = camera->fov_y_degrees == 0.0f ? DEFAULT_FOV_DEGREES : (double)camera->fov_y_degrees;
    if (!(fov > 0.0 && fov < 180.0))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_camera.fov_y_degrees %g is outside (0, 180)", fov);

    dvec3 view = dsub(target, eye);
    double view_len = dlength(view);
    /* Finite inputs can still overflow the difference (e.g. eye 3e38, target -3e38). */
    if (!isfinite(view_len) || view_len == 0.0)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_camera: target - eye has no usable direction");
    dvec3 forward = dscale(view, 1.0 / view_len);
    double up_len = dlength(up);
    if (!isfinite(up_len))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_camera.up is too large");
    dvec3 side = dcross(forward, dscale(up, 1.0 / up_len));
    if (!(dlength(side) >= MIN_UP_SIN))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_camera.up is parallel to the view direction");

    double half = tan(fov * 0.5 * 3.14159265358979323846 / 180.0);
    double aspect = (double)width / (double)height;
    dvec3 right_unit = dnormalize(side);
    dvec3 right = dscale(right_unit, half * aspect);
    dvec3 up_scaled = dscale(dcross(right_unit, forward), half);

    /* Every tracer starts from the float basis; the reference keeps it too (as doubles), so
     * "the exact ray of a pixel" is one ray all backends agree on, and a float tracer can
     * recompute it exactly in double to refine its hit distances (refine_hit_distance). */
    to_doubles(through_float(eye), out->eye);
    to_doubles(through_float(forward), out->forward);
    to_doubles(through_float(right), out->right);
    to_doubles(through_float(up_scaled), out->up);
    out->width = width;
    out->height = height;
    return VKRT_OK;
}

vkrt_result camera_setup(core *c, const vkrt_camera *camera, uint32_t width, uint32_t height,
                         vkrt_gpu_push *push)
{
    if (!push) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "camera_setup: NULL argument");
    camera_basis b;
    vkrt_result r = camera_setup_double(c, camera, width, height, &b);
    if (r != VKRT_OK) return r;
    push->eye = to_float3(b.eye);
    push->forward = to_float3(b.forward);
    push->right = to_float3(b.right);
    push->up = to_float3(b.up);
    push->width = width;
    push->height = height;
    return VKRT_OK;
}
