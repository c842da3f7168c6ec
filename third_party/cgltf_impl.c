/* The one translation unit holding cgltf's implementation; built with warnings relaxed. */
#define CGLTF_IMPLEMENTATION
#include <cgltf.h>
