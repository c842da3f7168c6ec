// The only C++ of the library: it turns tinyobjloader's callbacks into the C ones of
// tinyobj_shim.h and keeps every exception on this side of the boundary.
#include "tinyobj_shim.h"

#include <tiny_obj_loader.h>

#include <cstring>
#include <exception>
#include <fstream>
#include <istream>
#include <map>
#include <new>
#include <sstream>
#include <streambuf>
#include <string>
#include <vector>

namespace {

// Reads the caller's bytes in place, so a large file is not copied into a std::string.
class memory_buffer : public std::streambuf {
public:
    memory_buffer(const char *text, size_t size)
    {
        char *begin = const_cast<char *>(text);
        setg(begin, begin, begin + size);
    }
};

// Reads each .mtl file from one directory with tinyobjloader's own parser, and notes which of its
// materials state Pr: tinyobjloader keeps no such record, and its default roughness, 0, is also a
// value a file gives (a mirror), so "Pr 0" could not otherwise be told from no Pr at all.
class material_reader : public tinyobj::MaterialReader {
public:
    explicit material_reader(const std::string &directory) : directory_(directory) {}

    bool operator()(const std::string &name, std::vector<tinyobj::material_t> *materials,
                    std::map<std::string, int> *map, std::string *warn, std::string *err) override
    {
        std::ifstream file((directory_ + name).c_str(), std::ios::binary);
        if (!file) {
            if (warn) *warn += "Material file [ " + name + " ] not found in " + directory_ + "\n";
            return false;
        }
        std::ostringstream bytes;
        bytes << file.rdbuf();
        const std::string text = bytes.str();
        std::istringstream stream(text);
        tinyobj::LoadMtl(map, materials, &stream, warn, err);
        note_roughness(text);
        has_roughness.resize(materials->size(), false); // in case the two readings ever disagree
        return true;
    }

    std::vector<bool> has_roughness; // per material read so far, in tinyobjloader's order

private:
    // Follows LoadMtl line by line: a material ends at the next `newmtl` (the unnamed one before
    // the first is dropped) and at the end of the file, which always adds the last.
    void note_roughness(const std::string &text)
    {
        bool named = false, current = false;
        size_t i = 0;
        while (i <= text.size()) {
            size_t end = text.find_first_of("\r\n", i);
            if (end == std::string::npos) end = text.size();
            std::string line = text.substr(i, end - i);
            i = end + 1;
            line = line.substr(0, std::strlen(line.c_str())); // LoadMtl reads up to a NUL
            size_t last = line.find_last_not_of(" \t");
            line = last == std::string::npos ? std::string() : line.substr(0, last + 1);
            const char *token = line.c_str() + std::strspn(line.c_str(), " \t");
            auto space = [](char ch) { return ch == ' ' || ch == '\t'; };
            if (std::strncmp(token, "newmtl", 6) == 0 && space(token[6])) {
                if (named) has_roughness.push_back(current);
                named = true;
                current = false;
            } else if (token[0] == 'P' && token[1] == 'r' && space(token[2])) {
                current = true;
            }
        }
        has_roughness.push_back(current);
    }

    std::string directory_;
};

struct context {
    const tinyobj_shim_callbacks *callbacks;
    std::vector<tinyobj_shim_corner> corners;
    const material_reader *materials;
};

void on_vertex(void *user, tinyobj::real_t x, tinyobj::real_t y, tinyobj::real_t z, tinyobj::real_t)
{
    const tinyobj_shim_callbacks *cb = static_cast<context *>(user)->callbacks;
    if (cb->vertex) cb->vertex(cb->user, static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
}

void on_normal(void *user, tinyobj::real_t x, tinyobj::real_t y, tinyobj::real_t z)
{
    const tinyobj_shim_callbacks *cb = static_cast<context *>(user)->callbacks;
    if (cb->normal) cb->normal(cb->user, static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
}

void on_texcoord(void *user, tinyobj::real_t u, tinyobj::real_t v, tinyobj::real_t)
{
    const tinyobj_shim_callbacks *cb = static_cast<context *>(user)->callbacks;
    if (cb->texcoord) cb->texcoord(cb->user, static_cast<float>(u), static_cast<float>(v));
}

void on_index(void *user, tinyobj::index_t *indices, int count)
{
    context *ctx = static_cast<context *>(user);
    if (!ctx->callbacks->face || count <= 0) return;
    ctx->corners.resize(static_cast<size_t>(count));
    for (int i = 0; i < count; i++) {
        ctx->corners[i].v = indices[i].vertex_index;
        ctx->corners[i].vt = indices[i].texcoord_index;
        ctx->corners[i].vn = indices[i].normal_index;
    }
    ctx->callbacks->face(ctx->callbacks->user, ctx->corners.data(), ctx->corners.size());
}

void on_group(void *user, const char **, int)
{
    const tinyobj_shim_callbacks *cb = static_cast<context *>(user)->callbacks;
    if (cb->group) cb->group(cb->user);
}

void on_object(void *user, const char *)
{
    const tinyobj_shim_callbacks *cb = static_cast<context *>(user)->callbacks;
    if (cb->group) cb->group(cb->user);
}

void on_materials(void *user, const tinyobj::material_t *materials, int count)
{
    const tinyobj_shim_callbacks *cb = static_cast<context *>(user)->callbacks;
    if (!cb->materials || count <= 0) return;
    std::vector<tinyobj_shim_material> out(static_cast<size_t>(count));
    for (int i = 0; i < count; i++) {
        const tinyobj::material_t &m = materials[i];
        tinyobj_shim_material &o = out[static_cast<size_t>(i)];
        o.name = m.name.c_str();
        for (int k = 0; k < 3; k++) {
            o.diffuse[k] = static_cast<float>(m.diffuse[k]);
            o.specular[k] = static_cast<float>(m.specular[k]);
            o.emission[k] = static_cast<float>(m.emission[k]);
        }
        o.shininess = static_cast<float>(m.shininess);
        o.dissolve = static_cast<float>(m.dissolve);
        o.metallic = static_cast<float>(m.metallic);
        o.roughness = static_cast<float>(m.roughness);
        const std::vector<bool> &has_roughness = static_cast<context *>(user)->materials->has_roughness;
        o.has_roughness = static_cast<size_t>(i) < has_roughness.size() && has_roughness[static_cast<size_t>(i)];
        o.diffuse_texture = m.diffuse_texname.c_str();
        o.emissive_texture = m.emissive_texname.c_str();
    }
    cb->materials(cb->user, out.data(), out.size());
}

void on_use_material(void *user, const char *, int index)
{
    const tinyobj_shim_callbacks *cb = static_cast<context *>(user)->callbacks;
    if (cb->use_material) cb->use_material(cb->user, index);
}

void set_message(char *message, size_t message_size, const char *text)
{
    if (!message || message_size == 0) return;
    std::strncpy(message, text, message_size - 1);
    message[message_size - 1] = '\0';
    // tinyobjloader ends its messages with a newline; the caller adds its own context.
    size_t n = std::strlen(message);
    while (n && (message[n - 1] == '\n' || message[n - 1] == '\r')) message[--n] = '\0';
}

} // namespace

extern "C" tinyobj_shim_status tinyobj_shim_parse(const char *text, size_t size, const char *material_dir,
                                                  const tinyobj_shim_callbacks *callbacks, char *message,
                                                  size_t message_size)
{
    set_message(message, message_size, "");
    try {
        context ctx;
        ctx.callbacks = callbacks;
        memory_buffer buffer(text, size);
        std::istream stream(&buffer);
        tinyobj::callback_t cb;
        cb.vertex_cb = on_vertex;
        cb.normal_cb = on_normal;
        cb.texcoord_cb = on_texcoord;
        cb.index_cb = on_index;
        cb.group_cb = on_group;
        cb.object_cb = on_object;
        cb.mtllib_cb = on_materials;
        cb.usemtl_cb = on_use_material;
        std::string warn, err;
        // A missing or broken .mtl only adds to warn and err: the faces keep the default material.
        material_reader reader(material_dir ? material_dir : "");
        ctx.materials = &reader;
        if (!tinyobj::LoadObjWithCallback(stream, cb, &ctx, material_dir ? &reader : nullptr, &warn, &err)) {
            set_message(message, message_size, err.empty() ? "tinyobjloader failed" : err.c_str());
            return TINYOBJ_SHIM_PARSE_ERROR;
        }
        return TINYOBJ_SHIM_OK;
    } catch (const std::bad_alloc &) {
        set_message(message, message_size, "out of memory");
        return TINYOBJ_SHIM_OUT_OF_MEMORY;
    } catch (const std::exception &e) {
        set_message(message, message_size, e.what());
        return TINYOBJ_SHIM_INTERNAL_ERROR;
    } catch (...) {
        set_message(message, message_size, "unknown exception");
        return TINYOBJ_SHIM_INTERNAL_ERROR;
    }
}
