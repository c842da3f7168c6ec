/* The mesh module: OBJ and glTF loading, triangle order, transforms, normals, normalisation,
 * the built-in scene, and a code plus a message naming the file for every kind of bad input. */
#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "failing_alloc.h"
#include "file_read.h"
#include "mesh.h"
#include "scene_pack.h"
#include "texture.h"

#define MODEL(rel) VKRT_MODELS_DIR "/" rel
#define DATA(rel) VKRT_TEST_DATA_DIR "/" rel

static core g_core;

static const char *temp_dir(void)
{
    static char dir[64];
    if (!dir[0]) {
        snprintf(dir, sizeof dir, "/tmp/vkrt_test_mesh_XXXXXX");
        if (!mkdtemp(dir)) {
            fprintf(stderr, "mkdtemp failed\n");
            exit(1);
        }
    }
    return dir;
}

/* Writes bytes to a file in the temporary directory and returns its path (static storage,
 * one of a few rotating slots so two paths can be alive at once). */
static const char *temp_file(const char *name, const void *bytes, size_t size)
{
    static char paths[4][256];
    static int slot;
    char *path = paths[slot++ % 4];
    snprintf(path, 256, "%s/%s", temp_dir(), name);
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(bytes, 1, size, f) != size) {
        fprintf(stderr, "cannot write %s\n", path);
        exit(1);
    }
    fclose(f);
    return path;
}

static const char *temp_text(const char *name, const char *text)
{
    return temp_file(name, text, strlen(text));
}

static void *read_whole(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    void *data = malloc((size_t)n + 1);
    *size = fread(data, 1, (size_t)n, f);
    ((char *)data)[*size] = '\0';
    fclose(f);
    return data;
}

static void remove_temp_dir(void)
{
    static const char *const names[] = { "inf.obj", "huge.obj", "zero_index.obj", "far_relative.obj", "forward.obj",
                                         "bad_normal.obj", "text.obj", "nul.obj", "empty_file.obj", "mesh.stl",
                                         "missing_bin.gltf", "unknown_ext.gltf", "meshopt.gltf", "truncated.glb",
                                         "truncated_header.glb", "bad_json.gltf", "glb_named.obj", "cycle.gltf",
                                         "no_scene.gltf", "nan.gltf", "UPPER.OBJ", "light_nan.gltf",
                                         "light_inf.gltf", "light_negative.gltf", "light_overflow.gltf",
                                         "light_unknown.gltf", "light_flat.gltf", "ten_bytes.bin",
                                         "empty.bin", "plain_data_uri.gltf" };
    char path[256];
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        snprintf(path, sizeof path, "%s/%s", temp_dir(), names[i]);
        remove(path);
    }
    rmdir(temp_dir());
}

static vkrt_result load(const char *path, mesh *m)
{
    core_clear_error(&g_core);
    return mesh_load(&g_core, path, m);
}

static const float *corner(const mesh *m, uint32_t tri, int k)
{
    return m->positions + (size_t)tri * 9 + 3 * k;
}

static const float *corner_normal(const mesh *m, uint32_t tri, int k)
{
    return m->normals + (size_t)tri * 9 + 3 * k;
}

static void check_corner(const mesh *m, uint32_t tri, int k, float x, float y, float z, double eps)
{
    if (tri >= m->tri_count) {
        CHECK_MSG(tri < m->tri_count, "triangle %u of %u", tri, m->tri_count);
        return;
    }
    const float *p = corner(m, tri, k);
    CHECK_MSG(fabs(p[0] - x) <= eps && fabs(p[1] - y) <= eps && fabs(p[2] - z) <= eps,
              "triangle %u corner %d is (%.9g %.9g %.9g), expected (%.9g %.9g %.9g)", tri, k, p[0], p[1], p[2], x, y, z);
}

static void check_normal(const mesh *m, uint32_t tri, int k, float x, float y, float z, double eps)
{
    if (tri >= m->tri_count) return;
    const float *n = corner_normal(m, tri, k);
    CHECK_MSG(fabs(n[0] - x) <= eps && fabs(n[1] - y) <= eps && fabs(n[2] - z) <= eps,
              "triangle %u corner %d normal is (%.9g %.9g %.9g), expected (%.9g %.9g %.9g)", tri, k, n[0], n[1], n[2],
              x, y, z);
}

/* Every position finite and every normal of unit length. */
static void check_sane(const mesh *m, const char *what)
{
    size_t bad_positions = 0, bad_normals = 0;
    for (size_t i = 0; i < (size_t)m->tri_count * 3; i++) {
        const float *p = m->positions + 3 * i, *n = m->normals + 3 * i;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2])) bad_positions++;
        double len = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
        if (!(fabs(len - 1.0) < 1e-5)) bad_normals++;
    }
    CHECK_MSG(bad_positions == 0, "%s: %zu non-finite corners", what, bad_positions);
    CHECK_MSG(bad_normals == 0, "%s: %zu normals not of unit length", what, bad_normals);
}

static void expect_triangles(const char *path, uint32_t expected)
{
    mesh m;
    vkrt_result r = load(path, &m);
    CHECK_MSG(r == VKRT_OK, "%s: %s", path, g_core.last_error);
    CHECK_MSG(m.tri_count == expected, "%s: %u triangles, expected %u", path, m.tri_count, expected);
    check_sane(&m, path);
    mesh_destroy(&g_core, &m);
}

/* The call fails with `code`, the message names the file and holds `detail` (if given), and
 * the mesh is left empty. */
static void expect_failure(const char *path, vkrt_result code, const char *detail)
{
    mesh m;
    memset(&m, 0xab, sizeof m); /* loaders must not rely on a zeroed mesh */
    vkrt_result r = load(path, &m);
    CHECK_MSG(r == code, "%s: got %s (%s), expected %s", path, vkrt_result_string(r), g_core.last_error,
              vkrt_result_string(code));
    const char *slash = strrchr(path, '/');
    const char *name = slash ? slash + 1 : path;
    CHECK_MSG(strstr(g_core.last_error, name) != NULL, "message \"%s\" does not name %s", g_core.last_error, name);
    if (detail)
        CHECK_MSG(strstr(g_core.last_error, detail) != NULL, "message \"%s\" lacks \"%s\"", g_core.last_error, detail);
    CHECK(m.tri_count == 0 && m.positions == NULL && m.normals == NULL);
    mesh_destroy(&g_core, &m);
}

/* ---- OBJ ------------------------------------------------------------------------------ */

static void obj_quads_and_ngons_are_fanned_from_the_first_corner(void)
{
    expect_triangles(MODEL("obj/draco/cube_quads.obj"), 12);
    mesh m;
    CHECK(load(MODEL("obj/draco/octagon.obj"), &m) == VKRT_OK);
    CHECK_EQ_U64(m.tri_count, 6);
    static const float v[8][3] = { { 0, 1, 1 }, { 0, 2, 2 }, { 1, 3, 4 }, { 2, 3, 5 },
                                   { 3, 2, 5 }, { 3, 1, 4 }, { 2, 0, 2 }, { 1, 0, 1 } };
    for (uint32_t t = 0; t < m.tri_count; t++) {
        check_corner(&m, t, 0, v[0][0], v[0][1], v[0][2], 0);
        check_corner(&m, t, 1, v[t + 1][0], v[t + 1][1], v[t + 1][2], 0);
        check_corner(&m, t, 2, v[t + 2][0], v[t + 2][1], v[t + 2][2], 0);
    }
    mesh_destroy(&g_core, &m);
    expect_triangles(MODEL("obj/tinyobjloader/issue-319-002.obj"), 14);
    expect_triangles(MODEL("obj/pywavefront/arbitrary-faces.obj"), 17);
    expect_triangles(MODEL("obj/assimp/concave_polygon.obj"), 64); /* one 66-corner face */
}

static void obj_negative_indices_are_relative_to_the_vertices_so_far(void)
{
    mesh m;
    CHECK(load(MODEL("obj/tinyobjloader/cornell_box.obj"), &m) == VKRT_OK);
    CHECK_EQ_U64(m.tri_count, 36);
    /* The floor's three quads come first; then "o light" with f -4 -3 -2 -1. */
    check_corner(&m, 6, 0, 343.0f, 548.0f, 227.0f, 0);
    check_corner(&m, 6, 1, 343.0f, 548.0f, 332.0f, 0);
    check_corner(&m, 6, 2, 213.0f, 548.0f, 332.0f, 0);
    check_corner(&m, 7, 2, 213.0f, 548.0f, 227.0f, 0);
    mesh_destroy(&g_core, &m);
    expect_triangles(MODEL("obj/pywavefront/simple_negative_indices.obj"), 2);
    /* A face may also name a vertex defined further down the file. */
    expect_triangles(temp_text("forward.obj", "f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"), 1);
}

static void obj_objects_and_groups_append_in_file_order_with_file_or_computed_normals(void)
{
    mesh m;
    CHECK_MSG(load(DATA("groups.obj"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.tri_count, 6);
    /* o first: a quad whose corners all carry vn 0 0.6 0.8. */
    check_corner(&m, 0, 0, 0, 0, 0, 0);
    check_corner(&m, 1, 2, 0, 1, 0, 0);
    for (int t = 0; t < 2; t++)
        for (int k = 0; k < 3; k++) check_normal(&m, (uint32_t)t, k, 0.0f, 0.6f, 0.8f, 1e-6);
    /* g second: relative indices, no normals: computed, facing +z. */
    check_corner(&m, 2, 0, 0, 0, 1, 0);
    check_corner(&m, 2, 2, 0, 1, 1, 0);
    for (int k = 0; k < 3; k++) check_normal(&m, 2, k, 0, 0, 1, 1e-6);
    /* o third: one corner lacks vn, so the file's "0 0 -1" is not used: computed +z. */
    check_corner(&m, 3, 0, 2, 0, 0, 0);
    check_corner(&m, 5, 2, 1.5f, 1, 0, 0);
    for (uint32_t t = 3; t < 6; t++)
        for (int k = 0; k < 3; k++) check_normal(&m, t, k, 0, 0, 1, 1e-6);
    mesh_destroy(&g_core, &m);
    expect_triangles(MODEL("obj/assimp/spider.obj"), 1368);              /* 19 groups, v/vt/vn */
    expect_triangles(MODEL("obj/pywavefront/simple_missing_normal.obj"), 4); /* "v/vt/" corners */
    expect_triangles(MODEL("obj/pywavefront/box/box-N3F_V3F.obj"), 12);  /* with normals */
    expect_triangles(MODEL("obj/pywavefront/box/box-V3F.obj"), 12);      /* without */
}

static void obj_file_normals_are_used_when_every_corner_has_one(void)
{
    mesh m;
    CHECK(load(MODEL("obj/pywavefront/simple_normals.obj"), &m) == VKRT_OK);
    size_t size;
    char *text = read_whole(MODEL("obj/pywavefront/simple_normals.obj"), &size);
    float vn[3] = { 0 };
    const char *line = text ? strstr(text, "\nvn ") : NULL;
    CHECK(line && sscanf(line + 4, "%f %f %f", &vn[0], &vn[1], &vn[2]) == 3);
    double len = sqrt(vn[0] * vn[0] + vn[1] * vn[1] + vn[2] * vn[2]);
    if (len > 0 && m.tri_count) check_normal(&m, 0, 0, (float)(vn[0] / len), (float)(vn[1] / len), (float)(vn[2] / len), 1e-6);
    free(text);
    mesh_destroy(&g_core, &m);
}

/* vt records reach the corners of faces that give one per corner, v flipped (OBJ's v = 0 is
 * the bottom of the image, vkrt's the top); others get (0, 0), and a texture index that names
 * no vt is dropped like a missing normal. */
static void obj_texture_coordinates_follow_the_faces(void)
{
    mesh m;
    CHECK_MSG(load(VKRT_TEST_DATA_DIR "/textured.obj", &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.tri_count, 4);
    CHECK(m.has_texcoords);
    static const float expected[4][6] = { { 0, 1, 1, 1, 1, 0 }, { 0, 1, 1, 0, 0, 0 }, { 0 }, { 0 } };
    for (uint32_t t = 0; t < m.tri_count && t < 4; t++)
        for (int k = 0; k < 6; k++)
            CHECK_MSG(m.texcoords[t * 6 + k] == expected[t][k], "triangle %u texcoord %d is %g, expected %g", t, k,
                      (double)m.texcoords[t * 6 + k], (double)expected[t][k]);
    /* No mtllib: every triangle has the default material. */
    CHECK_EQ_U64(m.material_count, 1);
    vkrt_material def = vkrt_material_default();
    CHECK(m.material_count && memcmp(&m.materials[0], &def, sizeof def) == 0);
    for (uint32_t t = 0; t < m.tri_count; t++) CHECK_EQ_U64(m.material_ids[t], 0);
    mesh_destroy(&g_core, &m);
}

/* glTF materials: pbrMetallicRoughness factors with the specification's defaults where absent,
 * one table entry per material used, the default material for a primitive without one, and
 * TEXCOORD_0 per corner. */
static void gltf_materials_and_texture_coordinates_load(void)
{
    mesh m;
    CHECK_MSG(load(MODEL("gltf/draco/Box/Box.gltf"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.material_count, 1);
    CHECK(!m.has_texcoords);
    if (m.material_count == 1) {
        const vkrt_material *red = &m.materials[0];
        CHECK(red->base_color[0] == 0.8f && red->base_color[1] == 0.0f && red->base_color[2] == 0.0f &&
              red->base_color[3] == 1.0f);
        CHECK(red->metallic == 0.0f && red->roughness == 1.0f); /* roughness absent: 1 */
    }
    mesh_destroy(&g_core, &m);

    CHECK_MSG(load(MODEL("gltf/draco/three_meshes_two_materials_one_no_material/"
                         "three_meshes_two_materials_one_no_material.gltf"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK(m.has_texcoords);
    CHECK_EQ_U64(m.material_count, 3);
    vkrt_material def = vkrt_material_default();
    size_t with_default = 0, textured = 0;
    for (uint32_t t = 0; t < m.tri_count; t++) {
        const vkrt_material *x = &m.materials[m.material_ids[t]];
        if (memcmp(x, &def, sizeof def) == 0) with_default++;
        else CHECK(x->base_color[0] == 1.0f && x->metallic == 1.0f && x->roughness == 1.0f);
        for (int k = 0; k < 6; k++) textured += m.texcoords[t * 6 + k] != 0.0f;
    }
    CHECK_MSG(with_default > 0 && with_default < m.tri_count, "%zu of %u triangles have the default material",
              with_default, m.tri_count);
    CHECK_MSG(textured > m.tri_count, "only %zu texture coordinates are not zero", textured);
    mesh_destroy(&g_core, &m);
}

static void obj_missing_material_files_do_not_matter(void)
{
    expect_triangles(MODEL("obj/tinyobjloader/missing_material_file.obj"), 36);
    expect_triangles(MODEL("obj/draco/test_sphere.obj"), 224);
    expect_triangles(MODEL("obj/assimp/testmixed.obj"), 12); /* points and lines mixed in */
}

/* ---- glTF ----------------------------------------------------------------------------- */

static bool same_triangles(const mesh *a, const mesh *b, double eps, bool normals)
{
    if (a->tri_count != b->tri_count) return false;
    for (size_t i = 0; i < (size_t)a->tri_count * 9; i++) {
        if (fabs(a->positions[i] - b->positions[i]) > eps) return false;
        if (normals && fabs(a->normals[i] - b->normals[i]) > 1e-5) return false;
    }
    return true;
}

static void gltf_loads_external_bin_base64_and_glb(void)
{
    mesh a, b;
    CHECK_MSG(load(MODEL("gltf/draco/Box/Box.gltf"), &a) == VKRT_OK, "%s", g_core.last_error);
    CHECK_MSG(load(MODEL("gltf/draco/Box/Box.glb"), &b) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(a.tri_count, 12);
    CHECK_EQ_U64(b.tri_count, 12);
    check_sane(&a, "Box.gltf");
    check_sane(&b, "Box.glb");
    /* The unit box under each file's root matrix: Box.gltf moves it to z = 2, this Box.glb
     * turns it about x, which leaves its bounds. */
    for (int j = 0; j < 3; j++) {
        CHECK_NEAR(a.bounds_min[j], j == 2 ? 1.5 : -0.5, 1e-6);
        CHECK_NEAR(a.bounds_max[j], j == 2 ? 2.5 : 0.5, 1e-6);
        CHECK_NEAR(b.bounds_min[j], -0.5, 1e-6);
        CHECK_NEAR(b.bounds_max[j], 0.5, 1e-6);
    }
    mesh_destroy(&g_core, &a);
    mesh_destroy(&g_core, &b);
    expect_triangles(MODEL("gltf/assimp/BoxTextured-Embedded/BoxTextured.gltf"), 12);
    expect_triangles(MODEL("gltf/assimp/BoxTextured-Binary/BoxTextured.glb"), 12);
    expect_triangles(MODEL("gltf/draco/SimpleSparseAccessor/SimpleSparseAccessor.gltf"), 12);
    expect_triangles(MODEL("gltf/draco/Fox/Fox.gltf"), 576); /* non-indexed, no normals */
}

static void gltf_index_types_strips_fans_and_non_indexed_give_the_same_square(void)
{
    static const char *const files[] = { "04", "05", "06", "11", "12", "13", "14", "15" };
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        char path[256];
        snprintf(path, sizeof path, MODEL("gltf/assimp/Mesh_PrimitiveMode/Mesh_PrimitiveMode_%s.gltf"), files[i]);
        mesh m;
        CHECK_MSG(load(path, &m) == VKRT_OK, "%s", g_core.last_error);
        CHECK_MSG(m.tri_count == 2, "%s: %u triangles", path, m.tri_count);
        double area = 0.0;
        for (uint32_t t = 0; t < m.tri_count; t++) {
            const float *p = corner(&m, t, 0), *q = corner(&m, t, 1), *r = corner(&m, t, 2);
            /* Signed area seen from +z: every triangle wound the same way (counter-clockwise). */
            double z = ((double)q[0] - p[0]) * ((double)r[1] - p[1]) - ((double)q[1] - p[1]) * ((double)r[0] - p[0]);
            CHECK_MSG(z > 0, "%s: triangle %u is wound clockwise", path, t);
            area += 0.5 * fabs(z);
            for (int k = 0; k < 3; k++) check_normal(&m, t, k, 0, 0, 1, 1e-6);
        }
        CHECK_MSG(fabs(area - 1.0) < 1e-6, "%s: the triangles cover %g, not the unit square", path, area);
        mesh_destroy(&g_core, &m);
    }
}

static void gltf_mesh_instanced_by_several_nodes_appears_at_each(void)
{
    mesh m;
    CHECK_MSG(load(MODEL("gltf/draco/CubeScaledInstances/cube_att.gltf"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.tri_count, 48);
    /* Node 5 has four parents: identity, scale 4 at y 2, scale 2 at x 2, scale 3 at x -2. */
    if (m.tri_count == 48) {
        float lo[4][3], hi[4][3];
        for (int inst = 0; inst < 4; inst++)
            for (int j = 0; j < 3; j++) {
                lo[inst][j] = INFINITY;
                hi[inst][j] = -INFINITY;
                for (uint32_t t = (uint32_t)inst * 12; t < (uint32_t)inst * 12 + 12; t++)
                    for (int k = 0; k < 3; k++) {
                        float v = corner(&m, t, k)[j];
                        lo[inst][j] = v < lo[inst][j] ? v : lo[inst][j];
                        hi[inst][j] = v > hi[inst][j] ? v : hi[inst][j];
                    }
            }
        static const float scale[4] = { 1, 4, 2, 3 }, centre[4][3] = { { 0, 0, 0 }, { 0, 2, 0 }, { 2, 0, 0 }, { -2, 0, 0 } };
        float size0 = hi[0][0] - lo[0][0];
        for (int inst = 0; inst < 4; inst++)
            for (int j = 0; j < 3; j++) {
                CHECK_NEAR(hi[inst][j] - lo[inst][j], size0 * scale[inst], 1e-4);
                CHECK_NEAR(0.5f * (hi[inst][j] + lo[inst][j]) - scale[inst] * 0.5f * (hi[0][j] + lo[0][j]),
                           centre[inst][j], 1e-4);
            }
    }
    mesh_destroy(&g_core, &m);
    expect_triangles(MODEL("gltf/draco/CesiumMilkTruck/CesiumMilkTruck.gltf"), 3624);
}

static void gltf_instances_under_a_transformed_parent_land_at_exact_world_positions(void)
{
    mesh m;
    CHECK_MSG(load(DATA("instanced.gltf"), &m) == VKRT_OK, "%s", g_core.last_error);
    /* Only the default scene: the node of scene 1 at x = 100 is not there. */
    CHECK_EQ_U64(m.tri_count, 4);
    /* Parent: T(10,0,0) S(2). Child a: T(1,0,0): (x,y,z) -> (2x + 12, 2y, 2z). */
    check_corner(&m, 0, 0, 12, 0, 0, 0);
    check_corner(&m, 0, 1, 14, 0, 0, 0);
    check_corner(&m, 0, 2, 14, 2, 0, 0);
    check_corner(&m, 1, 0, 12, 0, 0, 0);
    check_corner(&m, 1, 1, 14, 2, 0, 0);
    check_corner(&m, 1, 2, 12, 2, 0, 0);
    /* Child b: a matrix turning 90 degrees about z, then z - 4: (x,y,z) -> (10 - 2y, 2x, 2z - 8). */
    check_corner(&m, 2, 0, 10, 0, -8, 0);
    check_corner(&m, 2, 1, 10, 2, -8, 0);
    check_corner(&m, 2, 2, 8, 2, -8, 0);
    check_corner(&m, 3, 0, 10, 0, -8, 0);
    check_corner(&m, 3, 1, 8, 2, -8, 0);
    check_corner(&m, 3, 2, 8, 0, -8, 0);
    for (uint32_t t = 0; t < m.tri_count; t++)
        for (int k = 0; k < 3; k++) check_normal(&m, t, k, 0, 0, 1, 1e-6);
    CHECK_NEAR(m.bounds_min[0], 8, 0);
    CHECK_NEAR(m.bounds_max[0], 14, 0);
    CHECK_NEAR(m.bounds_min[2], -8, 0);
    mesh_destroy(&g_core, &m);
}

static void gltf_quantized_positions_load_through_khr_mesh_quantization(void)
{
    mesh q, f;
    CHECK_MSG(load(MODEL("gltf/derived/Duck_quantized.glb"), &q) == VKRT_OK, "%s", g_core.last_error);
    CHECK_MSG(load(MODEL("gltf/draco/Duck/Duck.glb"), &f) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(q.tri_count, 4212);
    check_sane(&q, "Duck_quantized.glb");
    /* Dequantised through the node transform, the duck fills the same box as the float one. */
    double extent = 0.0;
    for (int j = 0; j < 3; j++) extent = fmax(extent, f.bounds_max[j] - f.bounds_min[j]);
    for (int j = 0; j < 3; j++) {
        CHECK_NEAR(q.bounds_min[j], f.bounds_min[j], 0.01 * extent);
        CHECK_NEAR(q.bounds_max[j], f.bounds_max[j], 0.01 * extent);
    }
    mesh_destroy(&g_core, &q);
    mesh_destroy(&g_core, &f);
}

static void obj_and_gltf_of_the_same_mesh_give_the_same_triangles_in_order(void)
{
    mesh o, g;
    CHECK_MSG(load(DATA("pair.obj"), &o) == VKRT_OK, "%s", g_core.last_error);
    CHECK_MSG(load(DATA("pair.gltf"), &g) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(o.tri_count, 6);
    CHECK(same_triangles(&o, &g, 1e-6, true));
    mesh_destroy(&g_core, &o);
    mesh_destroy(&g_core, &g);
}

/* ---- normals, bounds, normalisation --------------------------------------------------- */

static void computed_normals_are_unit_and_point_outward_on_closed_convex_meshes(void)
{
    static const char *const files[] = { DATA("octahedron.obj"), DATA("pair.obj"), MODEL("obj/draco/cube_subd.obj"),
                                         MODEL("obj/draco/cube_quads.obj") };
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        mesh m;
        CHECK_MSG(load(files[i], &m) == VKRT_OK, "%s", g_core.last_error);
        check_sane(&m, files[i]);
        /* The bounding-box centre is inside these shapes. */
        double c[3];
        for (int j = 0; j < 3; j++) c[j] = 0.5 * (m.bounds_min[j] + m.bounds_max[j]);
        size_t inward = 0;
        for (size_t v = 0; v < (size_t)m.tri_count * 3; v++) {
            const float *p = m.positions + 3 * v, *n = m.normals + 3 * v;
            if ((p[0] - c[0]) * n[0] + (p[1] - c[1]) * n[1] + (p[2] - c[2]) * n[2] <= 0) inward++;
        }
        CHECK_MSG(inward == 0, "%s: %zu corner normals point inward", files[i], inward);
        mesh_destroy(&g_core, &m);
    }
    /* Angle weighting: the octahedron's vertex normals are its axes exactly. */
    mesh m;
    CHECK(load(DATA("octahedron.obj"), &m) == VKRT_OK);
    check_normal(&m, 0, 0, 1, 0, 0, 1e-6);
    check_normal(&m, 0, 2, 0, 0, 1, 1e-6);
    mesh_destroy(&g_core, &m);
}

static void append_transforms_normals_by_the_inverse_transpose(void)
{
    /* A triangle in the plane x + y = 1, normal (1,1,0)/sqrt2; scaling x by 2 turns the
     * plane into x/2 + y = 1, normal (1,2,0)/sqrt5. */
    const float p[9] = { 1, 0, 0, 0, 1, 0, 1, 0, 1 };
    const float s = (float)(1.0 / sqrt(2.0));
    const float n[9] = { s, s, 0, s, s, 0, s, s, 0 };
    const float scale_x2[16] = { 2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    const float e = (float)(1.0 / sqrt(5.0));
    for (int given = 0; given < 2; given++) {
        mesh m = { 0 };
        vkrt_result r = mesh_append_indexed(&g_core, &m,
                                            &(mesh_primitive){ .positions = p, .vertex_count = 3,
                                                               .normals = given ? n : NULL, .transform = scale_x2 },
                                            "test", "tilted");
        CHECK(r == VKRT_OK);
        check_corner(&m, 0, 0, 2, 0, 0, 0);
        check_corner(&m, 0, 2, 2, 0, 1, 0);
        /* Winding (1,0,0) (0,1,0) (1,0,1) faces the +(1,1,0) side, so given and computed agree. */
        for (int k = 0; k < 3; k++) check_normal(&m, 0, k, e, 2 * e, 0, 1e-6);
        mesh_destroy(&g_core, &m);
    }
}

static void append_keeps_computed_normals_outward_under_a_mirror(void)
{
    const float p[9] = { 0, 0, 0, 1, 0, 0, 0, 1, 0 }; /* counter-clockwise, facing +z */
    const float mirror_x[16] = { -1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    mesh m = { 0 };
    CHECK(mesh_append_indexed(&g_core, &m, &(mesh_primitive){ .positions = p, .vertex_count = 3, .transform = mirror_x },
                              "test", "mirrored") == VKRT_OK);
    check_corner(&m, 0, 1, -1, 0, 0, 0); /* corners keep their order */
    for (int k = 0; k < 3; k++) check_normal(&m, 0, k, 0, 0, 1, 1e-6);
    mesh_destroy(&g_core, &m);
}

static void append_keeps_degenerate_triangles_and_falls_back_to_face_normals(void)
{
    /* Triangle 0 has zero area; triangles 1 and 2 are the same triangle back to back, so
     * their shared vertices' normals cancel and each falls back to its own face normal. */
    const float p[12] = { 0, 0, 0, 1, 0, 0, 2, 0, 0, 0, 1, 0 };
    const uint32_t idx[9] = { 0, 1, 2, 0, 1, 3, 0, 3, 1 };
    mesh m = { 0 };
    CHECK(mesh_append_indexed(&g_core, &m,
                              &(mesh_primitive){ .positions = p, .vertex_count = 4, .indices = idx, .index_count = 9 },
                              "test", "degenerate") == VKRT_OK);
    CHECK_EQ_U64(m.tri_count, 3);
    check_sane(&m, "degenerate");
    for (int k = 0; k < 3; k++) {
        check_normal(&m, 0, k, 0, 0, 1, 0);
        check_normal(&m, 1, k, 0, 0, 1, 1e-6);
        check_normal(&m, 2, k, 0, 0, -1, 1e-6);
    }
    mesh_destroy(&g_core, &m);
}

static void append_rejects_non_finite_coordinates_and_bad_indices_naming_the_culprit(void)
{
    const float p[12] = { 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, NAN, 0 };
    const uint32_t idx[3] = { 0, 1, 2 }, bad[3] = { 0, 1, 4 };
    mesh m = { 0 };
    vkrt_result r = mesh_append_indexed(&g_core, &m, &(mesh_primitive){ .positions = p, .vertex_count = 4, .indices = idx, .index_count = 3 },
                                        "nan.obj", "object 0");
    CHECK(r == VKRT_ERROR_INVALID_GEOMETRY);
    CHECK_MSG(strstr(g_core.last_error, "nan.obj") && strstr(g_core.last_error, "object 0") &&
                  strstr(g_core.last_error, "vertex 3") && strstr(g_core.last_error, "nan"),
              "%s", g_core.last_error);
    r = mesh_append_indexed(&g_core, &m, &(mesh_primitive){ .positions = p, .vertex_count = 3, .indices = bad, .index_count = 3 },
                            "x.gltf", "mesh 1 primitive 2");
    CHECK(r == VKRT_ERROR_INVALID_GEOMETRY);
    CHECK_MSG(strstr(g_core.last_error, "x.gltf: mesh 1 primitive 2") && strstr(g_core.last_error, "4"), "%s", g_core.last_error);
    r = mesh_append_indexed(&g_core, &m, &(mesh_primitive){ .positions = p, .vertex_count = 3, .indices = idx, .index_count = 2 },
                            "x.gltf", "mesh 0");
    CHECK(r == VKRT_ERROR_INVALID_GEOMETRY);
    CHECK_EQ_U64(m.tri_count, 0);
    mesh_destroy(&g_core, &m);
}

static void normalize_puts_the_bounds_in_the_unit_cube_with_largest_extent_one(void)
{
    static const char *const files[] = { MODEL("meshes/bunny.obj"), DATA("instanced.gltf"), MODEL("gltf/draco/Box/Box.glb") };
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        mesh m;
        CHECK(load(files[i], &m) == VKRT_OK);
        CHECK(mesh_normalize(&g_core, &m, files[i]) == VKRT_OK);
        float lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY, -INFINITY, -INFINITY };
        for (size_t v = 0; v < (size_t)m.tri_count * 3; v++)
            for (int j = 0; j < 3; j++) {
                lo[j] = fminf(lo[j], m.positions[3 * v + j]);
                hi[j] = fmaxf(hi[j], m.positions[3 * v + j]);
            }
        double extent = 0.0;
        for (int j = 0; j < 3; j++) {
            CHECK(lo[j] >= -0.5f - 1e-6f && hi[j] <= 0.5f + 1e-6f);
            CHECK_NEAR(0.5 * (lo[j] + hi[j]), 0.0, 1e-6);
            CHECK(m.bounds_min[j] == lo[j] && m.bounds_max[j] == hi[j]);
            extent = fmax(extent, (double)hi[j] - lo[j]);
        }
        CHECK_NEAR(extent, 1.0, 1e-6);
        check_sane(&m, files[i]);
        mesh_destroy(&g_core, &m);
    }
    /* A single point's worth of extent: only centred, never divided by zero. */
    const float p[9] = { 3, 3, 3, 3, 3, 3, 3, 3, 3 };
    mesh m = { 0 };
    CHECK(mesh_append_indexed(&g_core, &m, &(mesh_primitive){ .positions = p, .vertex_count = 3 }, "test", "point") == VKRT_OK);
    CHECK(mesh_normalize(&g_core, &m, "test") == VKRT_OK);
    check_corner(&m, 0, 0, 0, 0, 0, 0);
    mesh_destroy(&g_core, &m);
}

/* 3e38 and -3e38 are finite floats, but their distance is not: the mesh is refused, by name,
 * and left as it was. */
static void normalize_refuses_an_extent_beyond_float(void)
{
    const float p[9] = { 3e38f, 0, 0, -3e38f, 0, 0, 0, 1, 0 };
    mesh m = { 0 };
    CHECK(mesh_append_indexed(&g_core, &m, &(mesh_primitive){ .positions = p, .vertex_count = 3 }, "huge.obj", "object 0") == VKRT_OK);
    CHECK(mesh_normalize(&g_core, &m, "huge.obj") == VKRT_ERROR_INVALID_GEOMETRY);
    CHECK_MSG(strstr(g_core.last_error, "huge.obj") && strstr(g_core.last_error, "float range"), "message \"%s\"",
              g_core.last_error);
    CHECK(m.tri_count == 1 && m.positions[0] == 3e38f && m.positions[3] == -3e38f);
    mesh_destroy(&g_core, &m);
}

/* ---- the model set --------------------------------------------------------------------- */

/* Every OBJ/glTF/GLB row of MANIFEST.md with a triangle count loads to that count ("N unique
 * / M in scene": M), a count of 0 is VKRT_ERROR_EMPTY_SCENE, and `prefix` selects rows. */
static void check_manifest(const char *prefix, size_t *out_rows)
{
    size_t size, rows = 0;
    char *text = read_whole(MODEL("MANIFEST.md"), &size);
    CHECK_MSG(text != NULL, "cannot read MANIFEST.md");
    if (!text) return;
    for (char *line = text; line && *line; line = strchr(line, '\n') ? strchr(line, '\n') + 1 : NULL) {
        if (strncmp(line, "| `", 3) != 0) continue;
        char rel[256];
        const char *end = strchr(line + 3, '`');
        if (!end || (size_t)(end - line - 3) >= sizeof rel) continue;
        memcpy(rel, line + 3, (size_t)(end - line - 3));
        rel[end - line - 3] = '\0';
        if (strncmp(rel, prefix, strlen(prefix)) != 0) continue;
        const char *ext = strrchr(rel, '.');
        if (!ext || (strcmp(ext, ".obj") && strcmp(ext, ".gltf") && strcmp(ext, ".glb"))) continue;
        /* | `path` | format | triangles | */
        const char *cell = strchr(end, '|');
        cell = cell ? strchr(cell + 1, '|') : NULL;
        if (!cell) continue;
        unsigned long expected = strtoul(cell + 1, NULL, 10);
        const char *scene = strstr(cell + 1, "/ ");
        const char *bar = strchr(cell + 1, '|');
        if (scene && bar && scene < bar) expected = strtoul(scene + 2, NULL, 10);
        char path[512];
        snprintf(path, sizeof path, MODEL("%s"), rel);
        rows++;
        if (strstr(rel, "issue-140-zero-face-idx")) {
            /* Index 0 is not OBJ; vkrt refuses it rather than guess. */
            expect_failure(path, VKRT_ERROR_INVALID_GEOMETRY, "index 0");
        } else if (expected == 0) {
            expect_failure(path, VKRT_ERROR_EMPTY_SCENE, "only points or lines");
        } else {
            expect_triangles(path, (uint32_t)expected);
        }
    }
    free(text);
    *out_rows = rows;
}

static void meshes_triangle_counts_match_the_manifest(void)
{
    size_t rows = 0;
    check_manifest("meshes/", &rows);
    CHECK_EQ_U64(rows, 11);
}

static void every_obj_and_gltf_of_the_model_set_matches_the_manifest(void)
{
    size_t rows = 0;
    check_manifest("obj/", &rows);
    CHECK(rows >= 40);
    check_manifest("gltf/", &rows);
    CHECK(rows >= 25);
}

/* ---- bad input ------------------------------------------------------------------------- */

static void missing_and_unreadable_files_are_io_errors_naming_the_file(void)
{
    expect_failure(DATA("does_not_exist.obj"), VKRT_ERROR_IO, "No such file");
    expect_failure(DATA("does_not_exist.gltf"), VKRT_ERROR_IO, "No such file");
    CHECK(mesh_load_gltf(&g_core, DATA("does_not_exist.glb"), &(mesh){ 0 }) == VKRT_ERROR_IO);
    CHECK(mesh_load_obj(&g_core, DATA("does_not_exist.obj"), &(mesh){ 0 }) == VKRT_ERROR_IO);
    expect_failure(VKRT_TEST_DATA_DIR, VKRT_ERROR_IO, NULL); /* a directory */
    /* Box.gltf's buffer, copied without its .bin. */
    size_t size;
    char *box = read_whole(MODEL("gltf/draco/Box/Box.gltf"), &size);
    CHECK(box != NULL);
    if (box) expect_failure(temp_file("missing_bin.gltf", box, size), VKRT_ERROR_IO, "Box0.bin");
    free(box);
}

/* file_read learns a file's length before it allocates: what a mesh claims about a file (a
 * byteLength of -20, a URI naming a directory) never becomes an allocation of that size. */
static void file_read_learns_the_length_before_it_allocates(void)
{
    failing_allocator counted = { 0 };
    core c;
    const vkrt_allocator allocator = failing_allocator_use(&counted);
    core_init(&c, &allocator, NULL, NULL);
    const char *ten = temp_file("ten_bytes.bin", "0123456789", 10);
    void *bytes = NULL;
    size_t size = 99;
    CHECK(file_read(&c, ten, 0, &bytes, &size) == FILE_READ_OK && size == 10 && !memcmp(bytes, "0123456789", 10));
    core_free(&c, bytes);
    CHECK(file_read(&c, ten, 4, &bytes, &size) == FILE_READ_OK && size == 4 && !memcmp(bytes, "0123", 4));
    core_free(&c, bytes);
    CHECK(counted.calls == 2 && counted.live == 0);
    CHECK(file_read(&c, ten, 11, &bytes, &size) == FILE_READ_TOO_SHORT && !bytes && size == 0);
    CHECK(file_read(&c, ten, (size_t)-20, &bytes, &size) == FILE_READ_TOO_SHORT && !bytes);
    CHECK(file_read(&c, temp_dir(), 0, &bytes, &size) == FILE_READ_NOT_A_FILE && !bytes);
    CHECK(file_read(&c, "/dev/zero", 0, &bytes, &size) == FILE_READ_NOT_A_FILE && !bytes);
    CHECK(file_read(&c, DATA("does_not_exist.obj"), 0, &bytes, &size) == FILE_READ_CANNOT_OPEN && !bytes);
    CHECK(strstr(file_read_status_text(FILE_READ_CANNOT_OPEN, errno), "No such file") != NULL);
    CHECK(counted.calls == 2); /* none of the failures allocated */
    CHECK(file_read(&c, temp_file("empty.bin", "", 0), 0, &bytes, &size) == FILE_READ_OK && bytes && size == 0);
    core_free(&c, bytes);
    counted.fail_at = counted.calls + 1;
    CHECK(file_read(&c, ten, 0, &bytes, &size) == FILE_READ_OUT_OF_MEMORY && !bytes);
    CHECK(counted.live == 0);
    /* What no allocation can be does not reach the allocator either. */
    long calls = counted.calls;
    CHECK(core_alloc(&c, (size_t)-20) == NULL && core_alloc(&c, (size_t)PTRDIFF_MAX + 1) == NULL);
    CHECK(counted.calls == calls);
}

static void obj_garbage_and_non_obj_text_are_parse_errors(void)
{
    expect_failure(DATA("garbage.obj"), VKRT_ERROR_PARSE, "binary");
    expect_failure(temp_file("nul.obj", "v 0 0 0\nv 1 0 0\n\0v 0 1 0\nf 1 2 3\n", 34), VKRT_ERROR_PARSE, "offset 16");
    expect_failure(temp_text("text.obj", "Dear reader,\nthis is a letter, not a mesh.\n"), VKRT_ERROR_PARSE, "not an OBJ file");
}

static void files_without_triangles_are_empty_scenes(void)
{
    expect_failure(DATA("empty.obj"), VKRT_ERROR_EMPTY_SCENE, "no faces");
    expect_failure(temp_text("empty_file.obj", ""), VKRT_ERROR_EMPTY_SCENE, "no faces");
    expect_failure(DATA("lines_points.obj"), VKRT_ERROR_EMPTY_SCENE, "only points or lines");
    expect_failure(MODEL("obj/tinyobjloader/line-prim.obj"), VKRT_ERROR_EMPTY_SCENE, "only points or lines");
    expect_failure(MODEL("obj/tinyobjloader/points-prim.obj"), VKRT_ERROR_EMPTY_SCENE, "only points or lines");
    expect_failure(MODEL("gltf/assimp/Mesh_PrimitiveMode/Mesh_PrimitiveMode_00.gltf"), VKRT_ERROR_EMPTY_SCENE,
                   "only points or lines");
}

static void obj_non_finite_coordinates_are_invalid_geometry(void)
{
    expect_failure(DATA("nan.obj"), VKRT_ERROR_INVALID_GEOMETRY, "vertex 3 has a non-finite coordinate (nan)");
    expect_failure(temp_text("inf.obj", "v 0 0 0\nv 1 -INF 0\nv 0 1 0\nf 1 2 3\n"), VKRT_ERROR_INVALID_GEOMETRY,
                   "line 2: vertex 2 has a non-finite coordinate (-INF)");
    expect_failure(temp_text("huge.obj", "v 0 0 0\nv 1 0 0\nv 0 1e39 0\nf 1 2 3\n"), VKRT_ERROR_INVALID_GEOMETRY,
                   "line 3: vertex 3");
    expect_failure(temp_text("bad_normal.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 NaN\nf 1//1 2//1 3//1\n"),
                   VKRT_ERROR_INVALID_GEOMETRY, "normal 1");
}

static void out_of_range_indices_are_invalid_geometry(void)
{
    expect_failure(DATA("bad_index.obj"), VKRT_ERROR_INVALID_GEOMETRY, "line 7: face 2 refers to vertex 9");
    expect_failure(temp_text("zero_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"), VKRT_ERROR_INVALID_GEOMETRY,
                   "index 0");
    expect_failure(temp_text("far_relative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n"),
                   VKRT_ERROR_INVALID_GEOMETRY, "relative index -4");
    expect_failure(DATA("bad_index.gltf"), VKRT_ERROR_INVALID_GEOMETRY, "index 2 is 7");
}

static void gltf_required_extensions_vkrt_cannot_decode_are_unsupported(void)
{
    expect_failure(DATA("draco_required.gltf"), VKRT_ERROR_UNSUPPORTED, "KHR_draco_mesh_compression");
    size_t size;
    char *text = read_whole(DATA("pair.gltf"), &size);
    CHECK(text != NULL);
    if (!text) return;
    /* The pair mesh, requiring extensions inserted after its opening brace. */
    char *doc = malloc(size + 256);
    snprintf(doc, size + 256, "{\"extensionsUsed\":[\"EXT_vkrt_unknown\"],\"extensionsRequired\":[\"EXT_vkrt_unknown\"],%s", text + 1);
    expect_failure(temp_text("unknown_ext.gltf", doc), VKRT_ERROR_UNSUPPORTED, "EXT_vkrt_unknown");
    snprintf(doc, size + 256, "{\"extensionsUsed\":[\"EXT_meshopt_compression\"],\"extensionsRequired\":[\"EXT_meshopt_compression\"],%s", text + 1);
    expect_failure(temp_text("meshopt.gltf", doc), VKRT_ERROR_UNSUPPORTED, "EXT_meshopt_compression");
    /* A data: URI that is not base64 is unsupported whatever its byteLength: the check of a
     * byteLength against its URI's text is for the base64 ones cgltf decodes. */
    expect_failure(temp_text("plain_data_uri.gltf", "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":-20,"
                                                    "\"uri\":\"data:application/octet-stream,AAAA\"}]}"),
                   VKRT_ERROR_UNSUPPORTED, "unsupported uri");
    /* Quantization alone is decoded, so requiring it is fine. */
    snprintf(doc, size + 256, "{\"extensionsUsed\":[\"KHR_mesh_quantization\"],\"extensionsRequired\":[\"KHR_mesh_quantization\"],%s", text + 1);
    expect_triangles(temp_text("no_scene.gltf", doc), 6);
    free(doc);
    free(text);
}

static void gltf_truncated_and_malformed_files_are_parse_errors(void)
{
    size_t size;
    unsigned char *glb = read_whole(MODEL("gltf/draco/Box/Box.glb"), &size);
    CHECK(glb != NULL && size > 100);
    if (!glb) return;
    expect_failure(temp_file("truncated.glb", glb, size - 40), VKRT_ERROR_PARSE, NULL);
    expect_failure(temp_file("truncated_header.glb", glb, 10), VKRT_ERROR_PARSE, NULL);
    /* Content decides over the extension: a GLB named .obj is read as glTF. */
    mesh m;
    CHECK(load(temp_file("glb_named.obj", glb, size), &m) == VKRT_OK && m.tri_count == 12);
    mesh_destroy(&g_core, &m);
    free(glb);
    expect_failure(temp_text("bad_json.gltf", "{\"asset\": {\"version\": \"2.0\"}, \"nodes\": [ {\"mesh\": 0 "),
                   VKRT_ERROR_PARSE, "JSON");
}

static void gltf_node_cycles_are_parse_errors_not_hangs(void)
{
    size_t size;
    char *text = read_whole(DATA("instanced.gltf"), &size);
    CHECK(text != NULL);
    if (!text) return;
    /* Node 1 ("a") also lists the parent as its child, and node 3 lists node 1, so cgltf's
     * single parent per node does not see the loop; the walk must. */
    char *doc = malloc(size + 64);
    char *a = strstr(text, "\"name\": \"a\",");
    char *other = strstr(text, "\"name\": \"other scene\",");
    CHECK(a && other);
    if (a && other) {
        size_t n = 0;
        n += (size_t)snprintf(doc + n, size + 64 - n, "%.*s\"children\": [0], ", (int)(a - text), text);
        n += (size_t)snprintf(doc + n, size + 64 - n, "%.*s\"children\": [1], ", (int)(other - a), a);
        snprintf(doc + n, size + 64 - n, "%s", other);
        mesh m;
        vkrt_result r = load(temp_text("cycle.gltf", doc), &m);
        CHECK_MSG(r == VKRT_ERROR_PARSE, "%s: %s", vkrt_result_string(r), g_core.last_error);
        CHECK(strstr(g_core.last_error, "cycle.gltf") != NULL);
        mesh_destroy(&g_core, &m);
    }
    free(doc);
    free(text);
}

static void unknown_extensions_are_unsupported_and_case_is_ignored(void)
{
    expect_failure(temp_text("mesh.stl", "solid x\nendsolid x\n"), VKRT_ERROR_UNSUPPORTED, "unknown mesh format");
    expect_triangles(temp_text("UPPER.OBJ", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), 1);
}

/* ---- built-in scene -------------------------------------------------------------------- */

static void builtin_scene_is_large_finite_unit_normalled_and_outward(void)
{
    mesh m;
    memset(&m, 0xab, sizeof m);
    CHECK(mesh_make_builtin(&g_core, &m) == VKRT_OK);
    CHECK(m.tri_count > 1000);
    check_sane(&m, "builtin");
    /* Each triangle's winding agrees with its vertex normals (smooth or flat). */
    size_t disagree = 0;
    for (uint32_t t = 0; t < m.tri_count; t++) {
        const float *p = corner(&m, t, 0), *q = corner(&m, t, 1), *r = corner(&m, t, 2), *n = corner_normal(&m, t, 0);
        double e1[3] = { q[0] - p[0], q[1] - p[1], q[2] - p[2] }, e2[3] = { r[0] - p[0], r[1] - p[1], r[2] - p[2] };
        double g[3] = { e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0] };
        if (g[0] * n[0] + g[1] * n[1] + g[2] * n[2] <= 0) disagree++;
    }
    CHECK_MSG(disagree == 0, "%zu triangles wound against their normals", disagree);
    /* Ground plane first: tilted 30 degrees toward the default camera on +z. */
    check_normal(&m, 0, 0, 0, (float)cos(30 * 3.14159265358979 / 180), 0.5f, 1e-6);
    CHECK(mesh_normalize(&g_core, &m, "built-in scene") == VKRT_OK);
    for (int j = 0; j < 3; j++) CHECK(m.bounds_min[j] >= -0.5f - 1e-6f && m.bounds_max[j] <= 0.5f + 1e-6f);
    mesh_destroy(&g_core, &m);
}

/* ---- allocation failure ---------------------------------------------------------------- */

/* cgltf 1.12 itself crashes when an allocation fails half-way through parsing (it records
 * an attribute count before allocating the attributes, then frees count entries of a NULL
 * array), so glTF files only have their large allocations failed: the file and token
 * buffers inside cgltf, which fail cleanly, and vkrt's own arrays. */
#define GLTF_FAILABLE_SIZE 4096

static void every_allocation_failure_is_out_of_memory_and_leaks_nothing(void)
{
    static const struct {
        const char *path; /* NULL: the built-in scene */
        size_t min_size;
    } cases[] = { { DATA("groups.obj"), 0 }, { MODEL("obj/draco/octagon.obj"), 0 }, { DATA("pbr.obj"), 0 },
                  { MODEL("gltf/draco/Duck/Duck.glb"), GLTF_FAILABLE_SIZE },
                  { MODEL("gltf/draco/CesiumMilkTruck/CesiumMilkTruck.gltf"), GLTF_FAILABLE_SIZE },
                  { MODEL("gltf/draco/CubeScaledInstances/cube_att.gltf"), 256 },
                  { NULL, 0 } };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const char *name = cases[i].path ? cases[i].path : "built-in scene";
        for (long n = 0;; n++) {
            failing_allocator a = { .fail_at = n + 1, .min_size = cases[i].min_size }; /* n: 0-based */
            core c;
            const vkrt_allocator allocator = failing_allocator_use(&a);
            core_init(&c, &allocator, NULL, NULL);
            mesh m;
            vkrt_result r = cases[i].path ? mesh_load(&c, cases[i].path, &m) : mesh_make_builtin(&c, &m);
            if (r == VKRT_OK) {
                CHECK_MSG(m.tri_count > 0, "%s", name);
                mesh_destroy(&c, &m);
                CHECK_MSG(a.live == 0, "%s: %ld allocations leaked", name, a.live);
                CHECK_MSG(n > 0, "%s: no allocation was failed", name);
                break;
            }
            CHECK_MSG(r == VKRT_ERROR_OUT_OF_MEMORY, "%s: failing allocation %ld gave %s (%s)", name, n,
                      vkrt_result_string(r), c.last_error);
            CHECK_MSG(a.live == 0, "%s: failing allocation %ld leaked %ld", name, n, a.live);
            CHECK(m.tri_count == 0 && m.positions == NULL);
            if (r != VKRT_ERROR_OUT_OF_MEMORY || n > 100000) break;
        }
    }
}

static char last_warning[1024]; /* every warning since it was last emptied, one per line */

/* .mtl materials: Kd (clamped to [0, 1]) and d the base colour, Ns the roughness of the same
 * lobe width, Ke the emission, map_Kd a texture beside the file; `usemtl` switches per face, an
 * unknown name gives the default, and a material used twice is one table entry. */
static void obj_mtl_materials_and_textures_follow_usemtl(void)
{
    mesh m;
    CHECK_MSG(load(VKRT_TEST_DATA_DIR "/materials.obj", &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.tri_count, 5);
    CHECK_EQ_U64(m.material_count, 3);
    CHECK_EQ_U64(m.texture_count, 1);
    if (m.tri_count != 5 || m.material_count != 3 || m.texture_count != 1) {
        mesh_destroy(&g_core, &m);
        return;
    }
    vkrt_material def = vkrt_material_default();
    const uint32_t *id = m.material_ids;
    CHECK(memcmp(&m.materials[id[0]], &def, sizeof def) == 0 && id[3] == id[0]);
    CHECK(id[1] == id[4] && id[1] != id[0] && id[2] != id[1] && id[2] != id[0]);
    const vkrt_material *red = &m.materials[id[1]], *checker = &m.materials[id[2]];
    CHECK(red->base_color[0] == 0.75f && red->base_color[1] == 0.25f && red->base_color[2] == 0.0f &&
          red->base_color[3] == 0.5f);
    CHECK_MSG(fabs(red->roughness - pow(2.0 / 16.0, 0.25)) < 1e-6, "Ns 14: roughness %g", (double)red->roughness);
    CHECK(red->emissive[0] == 2.0f && red->emissive[1] == 1.0f && red->emissive[2] == 0.0f && red->metallic == 0.0f);
    CHECK(m.material_textures[id[1]] == VKRT_NO_TEXTURE && m.material_textures[id[2]] == 0);
    CHECK(checker->base_color[0] == 1.0f && checker->base_color[3] == 1.0f && checker->roughness == 1.0f);
    CHECK(m.textures[0].width == 2 && m.textures[0].height == 2);
    /* Texel (1, 1) is white at alpha 128/255: linear 1, 1, 1 and alpha 0.502 as halves. */
    float texel[4];
    vkrt_gpu_texture t = { 0, 2, 2, 0 };
    texture_sample(&t, m.textures[0].texels, 0.75f, 0.75f, texel);
    CHECK_MSG(texel[0] == 1.0f && texel[1] == 1.0f && fabsf(texel[3] - 128.0f / 255.0f) < 1e-3f, "texel (1, 1): %g %g %g %g",
              (double)texel[0], (double)texel[1], (double)texel[2], (double)texel[3]);
    mesh_destroy(&g_core, &m);
}

static void on_log(void *user, vkrt_log_level level, const char *message)
{
    (void)user;
    size_t used = strlen(last_warning);
    if (level == VKRT_LOG_WARN) snprintf(last_warning + used, sizeof last_warning - used, "%s\n", message);
}

/* A JPEG written byte by byte: 8x8 grey, one component, every coefficient 0 (each Huffman
 * table one code of one bit: DC category 0, AC end of block). `before_frame` goes between the
 * quantisation table and the frame header, `after_scan` between the scan's data and EOI. */
typedef struct jpeg_bytes {
    uint8_t b[1024];
    size_t n;
} jpeg_bytes;

static void jpeg_put(jpeg_bytes *j, const uint8_t *bytes, size_t n)
{
    if (n == 0 || j->n + n > sizeof j->b) return; /* (too long: never with the segments below) */
    memcpy(j->b + j->n, bytes, n);
    j->n += n;
}

/* A DHT segment of one table whose 16 counts are each `count` (16 * count codes, values 0). */
static void jpeg_put_dht(jpeg_bytes *j, uint8_t table, uint8_t count)
{
    size_t codes = 16u * count, length = 2 + 17 + codes;
    uint8_t head[5 + 16] = { 0xFF, 0xC4, (uint8_t)(length >> 8), (uint8_t)length, table };
    memset(head + 5, count, 16);
    jpeg_put(j, head, sizeof head);
    uint8_t values[16 * 255] = { 0 };
    jpeg_put(j, values, codes);
}

static jpeg_bytes grey_jpeg(const uint8_t *prefix, size_t prefix_n, const uint8_t *before_frame, size_t before_n,
                            const uint8_t *after_scan, size_t after_n)
{
    jpeg_bytes j = { .n = 0 };
    static const uint8_t soi[] = { 0xFF, 0xD8 };
    uint8_t dqt[5 + 64] = { 0xFF, 0xDB, 0, 67, 0x00 };
    memset(dqt + 5, 1, 64);
    static const uint8_t sof[] = { 0xFF, 0xC0, 0, 11, 8, 0, 8, 0, 8, 1, 1, 0x11, 0 };
    static const uint8_t dc[] = { 0xFF, 0xC4, 0, 20, 0x00, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x00 };
    static const uint8_t ac[] = { 0xFF, 0xC4, 0, 20, 0x10, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x00 };
    static const uint8_t sos[] = { 0xFF, 0xDA, 0, 8, 1, 1, 0x00, 0, 63, 0 };
    static const uint8_t data[] = { 0x3F }; /* DC code 0, AC code 0 (end of block), then 1 bits */
    static const uint8_t eoi[] = { 0xFF, 0xD9 };
    jpeg_put(&j, prefix, prefix_n);
    jpeg_put(&j, soi, sizeof soi);
    jpeg_put(&j, dqt, sizeof dqt);
    jpeg_put(&j, before_frame, before_n);
    jpeg_put(&j, sof, sizeof sof);
    jpeg_put(&j, dc, sizeof dc);
    jpeg_put(&j, ac, sizeof ac);
    jpeg_put(&j, sos, sizeof sos);
    jpeg_put(&j, data, sizeof data);
    jpeg_put(&j, after_scan, after_n);
    jpeg_put(&j, eoi, sizeof eoi);
    return j;
}

/* The texture a JPEG gives (its index, or VKRT_NO_TEXTURE), and *grey its first texel's red. */
static uint32_t jpeg_texture(const jpeg_bytes *j, float *grey)
{
    mesh m = { 0 };
    uint32_t index = VKRT_NO_TEXTURE;
    last_warning[0] = '\0';
    CHECK(mesh_add_texture_image(&g_core, &m, j->b, j->n, VKRT_WRAP_REPEAT, VKRT_WRAP_REPEAT, TEXTURE_LINEAR,
                                 "grey.jpg", "test", "texture", &index) == VKRT_OK);
    *grey = -1.0f;
    if (index != VKRT_NO_TEXTURE) {
        float texel[4];
        vkrt_gpu_texture t = { 0, m.textures[index].width, m.textures[index].height, 0 };
        texture_sample(&t, m.textures[index].texels, 0.5f, 0.5f, texel);
        *grey = texel[0];
    }
    mesh_destroy(&g_core, &m);
    return index;
}

/* stb_image 2.27 builds a Huffman table from its 16 code counts without checking that they
 * total at most 256 and writes past the table's arrays (found by a fuzz_gltf run seeded with
 * JPEG textures). Such tables are refused before stb_image reads the file, wherever stb_image
 * would meet them: before the frame header (also behind fill bytes ahead of SOI) and between a
 * scan and the next marker. Bytes that stb_image skips, an APP1 segment's payload here, are not
 * read as a table, so a valid file holding FF C4 there still decodes. */
static void jpeg_huffman_tables_over_256_codes_are_refused_before_decoding(void)
{
    float grey;
    jpeg_bytes valid = grey_jpeg(NULL, 0, NULL, 0, NULL, 0);
    CHECK_MSG(jpeg_texture(&valid, &grey) == 0 && fabsf(grey - 128.0f / 255.0f) < 0.01f, "grey %g: %s", (double)grey,
              last_warning);

    /* An APP1 whose payload looks like a DHT of 16 x 255 codes. */
    uint8_t app1[4 + 4 + 21] = { 0xFF, 0xE1, 0, 2 + 4 + 21, 'E', 'x', 'i', 'f', 0xFF, 0xC4, 0x10, 0x13, 0x00 };
    memset(app1 + 13, 0xFF, 16);
    jpeg_bytes with_app = grey_jpeg(NULL, 0, app1, sizeof app1, NULL, 0);
    CHECK_MSG(jpeg_texture(&with_app, &grey) == 0 && fabsf(grey - 128.0f / 255.0f) < 0.01f, "grey %g: %s",
              (double)grey, last_warning);

    /* 256 codes (16 x 16) fill a table exactly: not refused (the image stays undecodable for
     * another reason or decodes; either way no warning about the table). */
    jpeg_bytes full = { .n = 0 };
    jpeg_put_dht(&full, 0x01, 16);
    jpeg_bytes at_limit = grey_jpeg(NULL, 0, full.b, full.n, NULL, 0);
    jpeg_texture(&at_limit, &grey);
    CHECK_MSG(!strstr(last_warning, "more than 256"), "warning: %s", last_warning);

    jpeg_bytes dht = { .n = 0 };
    jpeg_put_dht(&dht, 0x01, 17); /* 272 codes */
    static const uint8_t fill[] = { 0xFF, 0xFF };
    const jpeg_bytes refused[] = {
        grey_jpeg(NULL, 0, dht.b, dht.n, NULL, 0),
        grey_jpeg(fill, sizeof fill - 1, dht.b, dht.n, NULL, 0), /* FF FF D8: stb_image skips the fill */
        grey_jpeg(NULL, 0, NULL, 0, dht.b, dht.n),
    };
    for (size_t i = 0; i < sizeof refused / sizeof refused[0]; i++) {
        CHECK_MSG(jpeg_texture(&refused[i], &grey) == VKRT_NO_TEXTURE, "case %zu decoded", i);
        CHECK_MSG(strstr(last_warning, "grey.jpg") && strstr(last_warning, "Huffman table lists more than 256 codes"),
                  "case %zu: warning '%s'", i, last_warning);
    }
}

/* An allocator whose blocks come filled with one byte, as memory a process has used before may. */
static void *filled_alloc(void *user, size_t size)
{
    void *p = malloc(size);
    if (p) memset(p, *(const uint8_t *)user, size);
    return p;
}

static void filled_free(void *user, void *pointer)
{
    (void)user;
    free(pointer);
}

/* stb_image 2.27 decodes a scan with whatever Huffman table its selector names, defined by a DHT
 * or not, from a decoder struct it never clears: an undefined table's entries were the
 * allocator's leftovers (found by fuzz_gltf: a shift by 32 from such an entry, undefined
 * behaviour). The glue clears every block it hands stb_image, so the same file decodes to the
 * same texels whatever the memory held before: here a progressive JPEG whose AC scan names AC
 * table 1, which no DHT defines, decoded with blocks filled with 0x00, 0x05 and 0xBE. */
static void jpeg_scan_with_an_undefined_huffman_table_decodes_alike_from_any_memory(void)
{
    jpeg_bytes j = { .n = 0 };
    static const uint8_t head[] = { 0xFF, 0xD8, 0xFF, 0xC2, 0, 11, 8, 0, 8, 0, 8, 1, 1, 0x11, 0 };
    uint8_t dqt[5 + 64] = { 0xFF, 0xDB, 0, 67, 0x00 };
    memset(dqt + 5, 1, 64);
    static const uint8_t dc[] = { 0xFF, 0xC4, 0, 20, 0x00, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x00 };
    static const uint8_t dc_scan[] = { 0xFF, 0xDA, 0, 8, 1, 1, 0x00, 0, 0, 0, 0x7F };
    /* AC table 1 (the selector's low nibble) is never defined. */
    static const uint8_t ac_scan[] = { 0xFF, 0xDA, 0, 8, 1, 1, 0x01, 1, 63, 0, 0x55, 0xAA, 0x33, 0x0F, 0xFF, 0xD9 };
    jpeg_put(&j, head, 2);
    jpeg_put(&j, dqt, sizeof dqt);
    jpeg_put(&j, head + 2, sizeof head - 2);
    jpeg_put(&j, dc, sizeof dc);
    jpeg_put(&j, dc_scan, sizeof dc_scan);
    jpeg_put(&j, ac_scan, sizeof ac_scan);
    static const uint8_t fills[] = { 0x00, 0x05, 0xBE };
    uint32_t texels[3][2 * 64] = { { 0 } };
    uint32_t index[3];
    for (int f = 0; f < 3; f++) {
        core c;
        const vkrt_allocator filled = { filled_alloc, filled_free, (void *)&fills[f] };
        core_init(&c, &filled, NULL, NULL);
        mesh m = { 0 };
        index[f] = VKRT_NO_TEXTURE;
        CHECK(mesh_add_texture_image(&c, &m, j.b, j.n, VKRT_WRAP_REPEAT, VKRT_WRAP_REPEAT, TEXTURE_LINEAR, "scan.jpg",
                                     "test", "texture", &index[f]) == VKRT_OK);
        if (index[f] != VKRT_NO_TEXTURE && m.textures[0].width == 8 && m.textures[0].height == 8)
            memcpy(texels[f], m.textures[0].texels, sizeof texels[f]);
        mesh_destroy(&c, &m);
    }
    for (int f = 1; f < 3; f++) {
        CHECK_MSG(index[f] == index[0], "fill 0x%02x: texture %u, fill 0x00: %u", fills[f], index[f], index[0]);
        CHECK_MSG(!memcmp(texels[f], texels[0], sizeof texels[0]), "fill 0x%02x decodes other texels than 0x00",
                  fills[f]);
    }
}

/* Textures are PNG, JPEG, TGA or BMP (glTF allows the first two; OBJ exporters write all four);
 * stb_image's other decoders are not built, as its 16-bit PNM path read past its buffer (found
 * by fuzz_gltf) and its GIF decoder has published memory-safety bugs. Each image here is 1x1 or
 * 2x1, written byte by byte; the refused ones are a warning and no texture. */
static void texture_formats_are_png_jpeg_tga_and_bmp(void)
{
    /* 24-bit BMP, one pixel (B, G, R = 10, 20, 200), its row padded to four bytes. */
    static const uint8_t bmp[] = { 'B', 'M', 58, 0, 0, 0, 0, 0, 0, 0, 54, 0, 0, 0, 40, 0, 0, 0, 1, 0, 0, 0, 1, 0,
                                   0, 0, 1, 0, 24, 0, 0, 0, 0, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                                   0, 0, 0, 0, 0, 0, 10, 20, 200, 0 };
    /* Uncompressed true-colour TGA, one pixel (B, G, R = 10, 20, 200). */
    static const uint8_t tga[] = { 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 1, 0, 24, 0, 10, 20, 200 };
    /* 16-bit PGM (maxval 525), two pixels: the PNM read that overran. */
    static const uint8_t pgm16[] = { 'P', '5', '\n', '2', ' ', '1', '\n', '5', '2', '5', '\n', 1, 0, 2, 0 };
    static const uint8_t ppm[] = { 'P', '6', ' ', '1', ' ', '1', ' ', '2', '5', '5', '\n', 200, 20, 10 };
    /* GIF89a, 1x1, a two-colour table, one LZW-coded pixel (clear, 0, end: 0x44 0x01). */
    static const uint8_t gif[] = { 'G', 'I', 'F', '8', '9', 'a', 1, 0, 1, 0, 0x80, 0, 0, 200, 20, 10, 0, 0, 0,
                                   ',', 0, 0, 0, 0, 1, 0, 1, 0, 0, 2, 2, 0x44, 0x01, 0, ';' };
    /* Photoshop, 1x1 RGB, 8 bits, uncompressed. */
    static const uint8_t psd[] = { '8', 'B', 'P', 'S', 0, 1, 0, 0, 0, 0, 0, 0, 0, 3, 0, 0, 0, 1, 0, 0, 0, 1,
                                   0, 8, 0, 3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 200, 20, 10 };
    static const uint8_t hdr[] = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 1\n\x80\x40\x20\x81";
    const struct {
        const char *name;
        const uint8_t *bytes;
        size_t size;
        bool decodes;
    } images[] = {
        { "one.bmp", bmp, sizeof bmp, true },     { "one.tga", tga, sizeof tga, true },
        { "two.pgm", pgm16, sizeof pgm16, false }, { "one.ppm", ppm, sizeof ppm, false },
        { "one.gif", gif, sizeof gif, false },    { "one.psd", psd, sizeof psd, false },
        { "one.hdr", hdr, sizeof hdr - 1, false },
    };
    for (size_t i = 0; i < sizeof images / sizeof images[0]; i++) {
        mesh m = { 0 };
        uint32_t index = VKRT_NO_TEXTURE;
        last_warning[0] = '\0';
        CHECK(mesh_add_texture_image(&g_core, &m, images[i].bytes, images[i].size, VKRT_WRAP_REPEAT, VKRT_WRAP_REPEAT,
                                     TEXTURE_LINEAR, images[i].name, "test", "texture", &index) == VKRT_OK);
        if (images[i].decodes) {
            CHECK_MSG(index == 0 && m.texture_count == 1, "%s: %s", images[i].name, last_warning);
            if (index == 0) {
                float texel[4];
                vkrt_gpu_texture t = { 0, m.textures[0].width, m.textures[0].height, 0 };
                texture_sample(&t, m.textures[0].texels, 0.5f, 0.5f, texel);
                CHECK_MSG(fabsf(texel[0] - 200.0f / 255.0f) < 0.01f && fabsf(texel[2] - 10.0f / 255.0f) < 0.01f,
                          "%s: texel %g %g %g", images[i].name, (double)texel[0], (double)texel[1], (double)texel[2]);
            }
        } else {
            CHECK_MSG(index == VKRT_NO_TEXTURE && m.texture_count == 0, "%s decoded", images[i].name);
            CHECK_MSG(strstr(last_warning, images[i].name) && strstr(last_warning, "not a PNG, JPEG, TGA or BMP image"),
                      "%s: warning '%s'", images[i].name, last_warning);
        }
        mesh_destroy(&g_core, &m);
    }
}

/* Base colour textures: read from PNG files beside the glTF, one table entry per texture, each
 * material pointing at its own; a texture file that does not exist is a warning naming it, and
 * the material keeps its factors without a texture. */
static void gltf_base_colour_textures_load_and_a_missing_one_is_a_warning(void)
{
    mesh m;
    CHECK_MSG(load(MODEL("gltf/draco/three_meshes_two_materials_one_no_material/"
                         "three_meshes_two_materials_one_no_material.gltf"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.texture_count, 2);
    size_t textured = 0;
    for (uint32_t i = 0; i < m.material_count; i++) textured += m.material_textures[i] != VKRT_NO_TEXTURE;
    CHECK_EQ_U64(textured, 2);
    for (uint32_t i = 0; i < m.texture_count; i++)
        CHECK_MSG(m.textures[i].width >= 16 && m.textures[i].height >= 16 && m.textures[i].texels,
                  "texture %u is %ux%u", i, m.textures[i].width, m.textures[i].height);
    mesh_destroy(&g_core, &m);

    last_warning[0] = '\0';
    CHECK_MSG(load(VKRT_TEST_DATA_DIR "/missing_texture.gltf", &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.texture_count, 0);
    CHECK(m.material_count == 1 && m.material_textures[0] == VKRT_NO_TEXTURE && m.materials[0].base_color[2] == 1.0f);
    CHECK_MSG(strstr(last_warning, "does_not_exist.png") && strstr(last_warning, "missing_texture.gltf"),
              "warning: '%s'", last_warning);
    mesh_destroy(&g_core, &m);
}

/* ---- lights ---------------------------------------------------------------------------- */

/* text with its first `from` replaced by `to` (malloc'd); the test fails if from is missing. */
static char *replaced(const char *text, const char *from, const char *to)
{
    const char *at = strstr(text, from);
    CHECK_MSG(at != NULL, "'%s' not in the test file", from);
    size_t head = at ? (size_t)(at - text) : strlen(text), from_n = at ? strlen(from) : 0;
    char *out = malloc(strlen(text) + strlen(to) + 1);
    memcpy(out, text, head);
    strcpy(out + head, to);
    strcat(out, text + head + from_n);
    return out;
}

static void check_light(const mesh *m, uint32_t i, vkrt_light_type type, const float vector[3], const float color[3],
                        double eps)
{
    if (i >= m->light_count) {
        CHECK_MSG(i < m->light_count, "light %u of %u", i, m->light_count);
        return;
    }
    const vkrt_light *l = &m->lights[i];
    CHECK_MSG(l->type == type, "light %u has type %d, expected %d", i, (int)l->type, (int)type);
    for (int j = 0; j < 3; j++) {
        CHECK_MSG(fabs(l->vector[j] - vector[j]) <= eps, "light %u vector[%d] is %.9g, expected %.9g", i, j,
                  (double)l->vector[j], (double)vector[j]);
        CHECK_MSG(fabs(l->color[j] - color[j]) <= eps, "light %u color[%d] is %.9g, expected %.9g", i, j,
                  (double)l->color[j], (double)color[j]);
    }
}

/* lights.gltf: a directional light on a node rotated 90 degrees about x and scaled by 2 shines
 * along its rotated -Z, (0, 1, 0), unit length, with color times intensity; a point light under a
 * translated and scaled parent sits at its world origin, parent * child = (1 + 2 * 0.5, 2, 3);
 * lights come in node order. Normalising the triangle (0,0,0) (4,0,0) (0,2,0) (centre (2, 1, 0),
 * scale 1/4) moves the point lights the same way and divides their intensities by 16, so the
 * irradiance at the scaled distances is unchanged; the directional light stays. */
static void gltf_punctual_lights_load_at_their_nodes_and_move_with_normalisation(void)
{
    mesh m;
    CHECK_MSG(load(DATA("lights.gltf"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.tri_count, 1);
    CHECK_EQ_U64(m.light_count, 3);
    check_light(&m, 0, VKRT_LIGHT_DIRECTIONAL, (const float[3]){ 0, 1, 0 }, (const float[3]){ 2, 1, 0.5f }, 1e-6);
    check_light(&m, 1, VKRT_LIGHT_POINT, (const float[3]){ 2, 2, 3 }, (const float[3]){ 10, 10, 10 }, 1e-6);
    check_light(&m, 2, VKRT_LIGHT_POINT, (const float[3]){ 0, 1, 0 }, (const float[3]){ 0.5f, 1, 1 }, 1e-6);
    /* The irradiance light 1 gives corner (4, 0, 0), before and after. */
    const float *v = corner(&m, 0, 1);
    double d2 = 0.0;
    for (int j = 0; j < 3; j++) d2 += ((double)v[j] - m.lights[1].vector[j]) * ((double)v[j] - m.lights[1].vector[j]);
    double before = m.lights[1].color[0] / d2;
    CHECK(mesh_normalize(&g_core, &m, "lights.gltf") == VKRT_OK);
    check_light(&m, 0, VKRT_LIGHT_DIRECTIONAL, (const float[3]){ 0, 1, 0 }, (const float[3]){ 2, 1, 0.5f }, 1e-6);
    check_light(&m, 1, VKRT_LIGHT_POINT, (const float[3]){ 0, 0.25f, 0.75f },
                (const float[3]){ 0.625f, 0.625f, 0.625f }, 1e-6);
    check_light(&m, 2, VKRT_LIGHT_POINT, (const float[3]){ -0.5f, 0, 0 },
                (const float[3]){ 0.5f / 16, 1.0f / 16, 1.0f / 16 }, 1e-6);
    check_corner(&m, 0, 1, 0.5f, -0.25f, 0, 1e-6);
    d2 = 0.0;
    for (int j = 0; j < 3; j++) d2 += ((double)v[j] - m.lights[1].vector[j]) * ((double)v[j] - m.lights[1].vector[j]);
    CHECK_NEAR(m.lights[1].color[0] / d2, before, 1e-6 * before);
    mesh_destroy(&g_core, &m);
    CHECK(m.lights == NULL && m.light_count == 0);
}

/* A spot light is lit as a point light at its node, with a warning that names the file and the
 * light; an instanced node would add one light per instance, but one warning per light. */
static void gltf_spot_light_is_a_point_light_with_a_warning(void)
{
    mesh m;
    last_warning[0] = '\0';
    CHECK_MSG(load(DATA("lights.gltf"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK(m.light_count == 3 && m.lights[2].type == VKRT_LIGHT_POINT);
    CHECK_MSG(strstr(last_warning, "lights.gltf") && strstr(last_warning, "light 2") && strstr(last_warning, "spot") &&
                  strstr(last_warning, "cone"),
              "warning: '%s'", last_warning);
    mesh_destroy(&g_core, &m);
}

/* Values JSON cannot hold as floats (1e39), that cgltf reads as NaN, or that are negative are
 * VKRT_ERROR_PARSE naming the file and the light; so is a colour whose product with the
 * intensity overflows. A light of an unknown type, or a directional light on a node that flattens
 * its -Z axis, is ignored with a warning. */
static void gltf_lights_with_non_finite_or_negative_values_are_parse_errors(void)
{
    size_t size;
    char *text = read_whole(DATA("lights.gltf"), &size);
    CHECK(text != NULL);
    if (!text) return;
    static const struct {
        const char *file, *from, *to, *detail;
    } bad[] = {
        { "light_nan.gltf", "\"intensity\": 10", "\"intensity\": nan", "light 1 (node 3)" },
        { "light_inf.gltf", "\"intensity\": 10", "\"intensity\": 1e39", "light 1 (node 3)" },
        { "light_negative.gltf", "\"intensity\": 10", "\"intensity\": -1", "light 1 (node 3)" },
        { "light_overflow.gltf", "\"intensity\": 2", "\"intensity\": 1e30, \"color\": [ 1e30, 0, 0 ]",
          "light 0 (node 1)" },
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char *doc = replaced(text, bad[i].from, bad[i].to);
        expect_failure(temp_text(bad[i].file, doc), VKRT_ERROR_PARSE, bad[i].detail);
        free(doc);
    }
    static const struct {
        const char *file, *from, *to, *detail;
    } ignored[] = {
        { "light_unknown.gltf", "\"type\": \"point\"", "\"type\": \"area\"", "light 1 (node 3) has no type" },
        { "light_flat.gltf", "\"scale\": [ 2, 2, 2 ], \"extensions\"", "\"scale\": [ 2, 2, 0 ], \"extensions\"",
          "collapses its -Z axis" },
    };
    for (size_t i = 0; i < sizeof ignored / sizeof ignored[0]; i++) {
        char *doc = replaced(text, ignored[i].from, ignored[i].to);
        mesh m;
        last_warning[0] = '\0';
        CHECK_MSG(load(temp_text(ignored[i].file, doc), &m) == VKRT_OK, "%s", g_core.last_error);
        CHECK_EQ_U64(m.light_count, 2);
        CHECK_MSG(strstr(last_warning, ignored[i].file) && strstr(last_warning, ignored[i].detail), "warning: '%s'",
                  last_warning);
        mesh_destroy(&g_core, &m);
        free(doc);
    }
    free(text);
}

/* mesh_add_light answers the caller's code, naming the source and the light, for every value
 * that is not a light, and keeps the valid ones in order. */
static void add_light_validates_type_values_and_direction(void)
{
    const struct {
        vkrt_light light;
        const char *detail;
    } bad[] = {
        { { (vkrt_light_type)5, { 0, 1, 0 }, { 1, 1, 1 } }, "type 5" },
        { { VKRT_LIGHT_POINT, { 0, NAN, 0 }, { 1, 1, 1 } }, "position" },
        { { VKRT_LIGHT_DIRECTIONAL, { INFINITY, 0, 0 }, { 1, 1, 1 } }, "direction" },
        { { VKRT_LIGHT_POINT, { 0, 0, 0 }, { 1, -0.5f, 1 } }, "colour[1]" },
        { { VKRT_LIGHT_POINT, { 0, 0, 0 }, { 1, 1, NAN } }, "colour[2]" },
        { { VKRT_LIGHT_DIRECTIONAL, { 0, 0, 0 }, { 1, 1, 1 } }, "without a direction" },
    };
    mesh m = { 0 };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        core_clear_error(&g_core);
        CHECK_MSG(mesh_add_light(&g_core, &m, &bad[i].light, VKRT_ERROR_INVALID_ARGUMENT, "src", "light x") ==
                      VKRT_ERROR_INVALID_ARGUMENT,
                  "bad light %zu", i);
        CHECK_MSG(strstr(g_core.last_error, "src: light x") && strstr(g_core.last_error, bad[i].detail),
                  "bad light %zu: '%s'", i, g_core.last_error);
    }
    CHECK_EQ_U64(m.light_count, 0);
    /* A point light at the origin and a black one are lights; growth keeps them in order. */
    for (int i = 0; i < 9; i++) {
        vkrt_light l = { i % 2 ? VKRT_LIGHT_DIRECTIONAL : VKRT_LIGHT_POINT, { 0, 0, (float)(i % 2) },
                         { (float)i, 0, 0 } };
        CHECK(mesh_add_light(&g_core, &m, &l, VKRT_ERROR_INVALID_ARGUMENT, "src", "light") == VKRT_OK);
    }
    CHECK_EQ_U64(m.light_count, 9);
    for (uint32_t i = 0; i < m.light_count; i++) CHECK(m.lights[i].color[0] == (float)i);
    mesh_destroy(&g_core, &m);
}

/* A point light far from a tiny scene would leave the float range once the scene is scaled up:
 * refused by name before anything moves. */
static void normalize_refuses_a_point_light_pushed_beyond_float(void)
{
    const float p[9] = { 0, 0, 0, 1e-3f, 0, 0, 0, 1e-3f, 0 };
    mesh m = { 0 };
    CHECK(mesh_append_indexed(&g_core, &m, &(mesh_primitive){ .positions = p, .vertex_count = 3 }, "far.gltf",
                              "mesh 0") == VKRT_OK);
    const vkrt_light sun = { VKRT_LIGHT_DIRECTIONAL, { 0, -1, 0 }, { 1, 1, 1 } };
    const vkrt_light far = { VKRT_LIGHT_POINT, { 1e38f, 0, 0 }, { 1, 1, 1 } };
    CHECK(mesh_add_light(&g_core, &m, &sun, VKRT_ERROR_PARSE, "far.gltf", "light 0") == VKRT_OK);
    CHECK(mesh_add_light(&g_core, &m, &far, VKRT_ERROR_PARSE, "far.gltf", "light 1") == VKRT_OK);
    CHECK(mesh_normalize(&g_core, &m, "far.gltf") == VKRT_ERROR_INVALID_GEOMETRY);
    CHECK_MSG(strstr(g_core.last_error, "far.gltf") && strstr(g_core.last_error, "point light 1"), "message \"%s\"",
              g_core.last_error);
    CHECK(m.positions[3] == 1e-3f && m.lights[1].vector[0] == 1e38f && m.lights[1].color[0] == 1.0f);
    mesh_destroy(&g_core, &m);
}

/* ---- metallic-roughness and emissive textures ------------------------------------------ */

/* pbr_textures.gltf: one 1x1 image of (255, 128, 64) used as the metallic-roughness texture
 * (linear data: G 128 is 0.502, not sRGB's 0.216) and as the emissive one (sRGB colour), so it is
 * decoded once each way; the factors stay factors, and the packed GPU material names both
 * textures and no base colour one. */
static void gltf_metallic_roughness_texture_is_linear_and_emissive_srgb(void)
{
    mesh m;
    CHECK_MSG(load(DATA("pbr_textures.gltf"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.material_count, 1);
    CHECK_EQ_U64(m.texture_count, 2);
    if (m.material_count != 1 || m.texture_count != 2) {
        mesh_destroy(&g_core, &m);
        return;
    }
    const vkrt_material *mat = &m.materials[0];
    CHECK(mat->metallic == 0.5f && mat->roughness == 0.75f && mat->emissive[0] == 1.0f && mat->emissive[1] == 0.5f &&
          mat->emissive[2] == 0.25f);
    CHECK(mat->metallic_roughness_texture == NULL && mat->emissive_texture == NULL);
    uint32_t mr = m.material_metallic_roughness_textures[0], em = m.material_emissive_textures[0];
    CHECK(m.material_textures[0] == VKRT_NO_TEXTURE && mr < 2 && em < 2 && mr != em);
    if (mr >= 2 || em >= 2) {
        mesh_destroy(&g_core, &m);
        return;
    }
    float linear[4], srgb[4];
    vkrt_gpu_texture t = { 0, 1, 1, 0 };
    texture_sample(&t, m.textures[mr].texels, 0.5f, 0.5f, linear);
    texture_sample(&t, m.textures[em].texels, 0.5f, 0.5f, srgb);
    CHECK_NEAR(linear[0], 1.0, 0);
    CHECK_NEAR(linear[1], 128.0 / 255.0, 1e-3); /* roughness */
    CHECK_NEAR(linear[2], 64.0 / 255.0, 1e-3);  /* metallic */
    CHECK_NEAR(srgb[1], pow((128.0 / 255.0 + 0.055) / 1.055, 2.4), 1e-3);
    CHECK_NEAR(srgb[2], pow((64.0 / 255.0 + 0.055) / 1.055, 2.4), 1e-3);

    vkrt_gpu_surface surfaces[1];
    vkrt_gpu_material gpu[1];
    vkrt_gpu_texture textures[2];
    uint32_t texels[2 * 2];
    CHECK_EQ_U64(scene_texel_count(&m), 2);
    scene_pack_surfaces(&m, surfaces, gpu, textures, texels);
    CHECK(gpu[0].base_color_texture == VKRT_NO_TEXTURE);
    CHECK(gpu[0].metallic_roughness_texture == mr && gpu[0].emissive_texture == em);
    CHECK(gpu[0].metallic == 0.5f && gpu[0].roughness == 0.75f && gpu[0].emissive.y == 0.5f);
    mesh_destroy(&g_core, &m);
}

/* pbr.obj: Pr replaces the Ns roughness where given (Pr 0 included, though Ns says otherwise),
 * Pm is the metallic, map_Ke is an emissive texture (emission 1 where no Ke scales it, Ke where
 * one does), and map_Pr and map_Pm are not read (no warning for their missing files). */
static void obj_pbr_extension_and_emissive_maps_load(void)
{
    mesh m;
    last_warning[0] = '\0';
    CHECK_MSG(load(DATA("pbr.obj"), &m) == VKRT_OK, "%s", g_core.last_error);
    CHECK_EQ_U64(m.tri_count, 4);
    CHECK_EQ_U64(m.material_count, 4);
    CHECK_EQ_U64(m.texture_count, 2);
    CHECK_MSG(last_warning[0] == '\0', "warning: '%s'", last_warning);
    if (m.tri_count != 4 || m.material_count != 4) {
        mesh_destroy(&g_core, &m);
        return;
    }
    const uint32_t *id = m.material_ids;
    const vkrt_material *mirror = &m.materials[id[0]], *rough = &m.materials[id[1]], *glow = &m.materials[id[2]],
                        *tinted = &m.materials[id[3]];
    CHECK_MSG(mirror->roughness == 0.0f && mirror->metallic == 0.75f, "mirror_metal: roughness %g metallic %g",
              (double)mirror->roughness, (double)mirror->metallic);
    CHECK_MSG(fabs(rough->roughness - 0.4) < 1e-6 && rough->metallic == 0.0f, "rough: roughness %g",
              (double)rough->roughness);
    CHECK_MSG(fabs(glow->roughness - pow(2.0 / 16.0, 0.25)) < 1e-6, "glowing (Ns 14): roughness %g",
              (double)glow->roughness);
    for (int i = 0; i < 2; i++)
        CHECK(m.material_emissive_textures[id[i]] == VKRT_NO_TEXTURE && m.materials[id[i]].emissive[0] == 0.0f);
    for (int i = 0; i < 4; i++) {
        CHECK(m.material_metallic_roughness_textures[id[i]] == VKRT_NO_TEXTURE);
        CHECK(m.material_textures[id[i]] == VKRT_NO_TEXTURE);
    }
    CHECK(m.material_emissive_textures[id[2]] != VKRT_NO_TEXTURE &&
          m.material_emissive_textures[id[3]] != VKRT_NO_TEXTURE);
    CHECK(glow->emissive[0] == 1.0f && glow->emissive[1] == 1.0f && glow->emissive[2] == 1.0f);
    CHECK(tinted->emissive[0] == 2.0f && tinted->emissive[1] == 1.0f && tinted->emissive[2] == 0.5f);
    mesh_destroy(&g_core, &m);
}

int main(void)
{
    core_init(&g_core, NULL, on_log, NULL);
    RUN(obj_quads_and_ngons_are_fanned_from_the_first_corner);
    RUN(obj_negative_indices_are_relative_to_the_vertices_so_far);
    RUN(obj_objects_and_groups_append_in_file_order_with_file_or_computed_normals);
    RUN(obj_file_normals_are_used_when_every_corner_has_one);
    RUN(obj_missing_material_files_do_not_matter);
    RUN(gltf_loads_external_bin_base64_and_glb);
    RUN(gltf_index_types_strips_fans_and_non_indexed_give_the_same_square);
    RUN(gltf_mesh_instanced_by_several_nodes_appears_at_each);
    RUN(gltf_instances_under_a_transformed_parent_land_at_exact_world_positions);
    RUN(gltf_quantized_positions_load_through_khr_mesh_quantization);
    RUN(obj_and_gltf_of_the_same_mesh_give_the_same_triangles_in_order);
    RUN(computed_normals_are_unit_and_point_outward_on_closed_convex_meshes);
    RUN(append_transforms_normals_by_the_inverse_transpose);
    RUN(append_keeps_computed_normals_outward_under_a_mirror);
    RUN(append_keeps_degenerate_triangles_and_falls_back_to_face_normals);
    RUN(append_rejects_non_finite_coordinates_and_bad_indices_naming_the_culprit);
    RUN(normalize_puts_the_bounds_in_the_unit_cube_with_largest_extent_one);
    RUN(normalize_refuses_an_extent_beyond_float);
    RUN(meshes_triangle_counts_match_the_manifest);
    RUN(every_obj_and_gltf_of_the_model_set_matches_the_manifest);
    RUN(missing_and_unreadable_files_are_io_errors_naming_the_file);
    RUN(file_read_learns_the_length_before_it_allocates);
    RUN(obj_garbage_and_non_obj_text_are_parse_errors);
    RUN(files_without_triangles_are_empty_scenes);
    RUN(obj_non_finite_coordinates_are_invalid_geometry);
    RUN(out_of_range_indices_are_invalid_geometry);
    RUN(gltf_required_extensions_vkrt_cannot_decode_are_unsupported);
    RUN(gltf_truncated_and_malformed_files_are_parse_errors);
    RUN(gltf_node_cycles_are_parse_errors_not_hangs);
    RUN(unknown_extensions_are_unsupported_and_case_is_ignored);
    RUN(builtin_scene_is_large_finite_unit_normalled_and_outward);
    RUN(obj_texture_coordinates_follow_the_faces);
    RUN(gltf_materials_and_texture_coordinates_load);
    RUN(gltf_base_colour_textures_load_and_a_missing_one_is_a_warning);
    RUN(jpeg_huffman_tables_over_256_codes_are_refused_before_decoding);
    RUN(texture_formats_are_png_jpeg_tga_and_bmp);
    RUN(jpeg_scan_with_an_undefined_huffman_table_decodes_alike_from_any_memory);
    RUN(obj_mtl_materials_and_textures_follow_usemtl);
    RUN(gltf_punctual_lights_load_at_their_nodes_and_move_with_normalisation);
    RUN(gltf_spot_light_is_a_point_light_with_a_warning);
    RUN(gltf_lights_with_non_finite_or_negative_values_are_parse_errors);
    RUN(add_light_validates_type_values_and_direction);
    RUN(normalize_refuses_a_point_light_pushed_beyond_float);
    RUN(gltf_metallic_roughness_texture_is_linear_and_emissive_srgb);
    RUN(obj_pbr_extension_and_emissive_maps_load);
    RUN(every_allocation_failure_is_out_of_memory_and_leaks_nothing);
    remove_temp_dir();
    return check_exit();
}
