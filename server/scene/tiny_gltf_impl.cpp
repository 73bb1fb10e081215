// tinygltf's implementation, compiled here rather than taken from Debian's libtinygltf.so so
// that it decodes Draco-compressed meshes (KHR_draco_mesh_compression, Debian's
// libdraco-dev): the library as packaged is built without it. Images are decoded by
// Debian's libstb (stb_image), as the packaged library does; nothing else differs.
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_ENABLE_DRACO
#include <tiny_gltf.h>
