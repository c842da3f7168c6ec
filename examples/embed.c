/* Embedding vkrt: render the built-in scene (or a mesh file) to a PNG through the public API.
 * Usage: embed OUT.png [MESH]
 * Build: cc embed.c $(pkg-config --static --cflags --libs vkrt) */
#include <stdio.h>
#include <stdlib.h>

#include <vkrt.h>

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: embed OUT.png [MESH]\n");
        return 2;
    }
    if (vkrt_version() != VKRT_VERSION) {
        fprintf(stderr, "embed: vkrt.h and libvkrt.a are different versions\n");
        return 1;
    }
    vkrt_context *ctx;
    vkrt_result r = vkrt_context_create(&(vkrt_context_desc){ 0 }, &ctx);
    if (r != VKRT_OK) {
        fprintf(stderr, "embed: %s\n", vkrt_result_string(r));
        return 1;
    }
    /* No path: the built-in procedural scene. */
    vkrt_scene *scene;
    r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ .path = argc > 2 ? argv[2] : NULL }, &scene);
    if (r != VKRT_OK) {
        fprintf(stderr, "embed: %s\n", vkrt_context_last_error(ctx));
        vkrt_context_destroy(ctx);
        return 1;
    }
    const uint32_t w = 64, h = 64;
    size_t n = vkrt_render_floats(w, h);
    float *rgba = malloc(n * sizeof *rgba);
    int code = 1;
    if (!rgba) goto done;
    r = vkrt_render(ctx, scene, &(vkrt_render_desc){ .width = w, .height = h }, rgba, n, NULL);
    if (r != VKRT_OK) {
        fprintf(stderr, "embed: render: %s\n", vkrt_context_last_error(ctx));
        goto done;
    }
    /* Normal mode: alpha is 1 where the ray hit, 0 where it missed. */
    size_t hits = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) hits += rgba[i * 4 + 3] > 0.0f;
    if (hits == 0 || hits == (size_t)w * h) {
        fprintf(stderr, "embed: %zu of %u pixels hit: the camera does not frame the scene\n", hits, w * h);
        goto done;
    }
    r = vkrt_image_save(ctx, argv[1], &(vkrt_image_view){ .rgba = rgba, .width = w, .height = h, .mode = VKRT_MODE_NORMAL });
    if (r != VKRT_OK) {
        fprintf(stderr, "embed: %s\n", vkrt_context_last_error(ctx));
        goto done;
    }
    printf("embed: %ux%u on %s, %zu pixels hit -> %s\n", w, h, vkrt_context_device_name(ctx), hits, argv[1]);
    code = 0;
done:
    free(rgba);
    vkrt_scene_destroy(scene);
    vkrt_context_destroy(ctx);
    return code;
}
