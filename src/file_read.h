/* Reading a file, whole or its first bytes, into a block from the core's allocator. The
 * length comes from fstat() before anything is allocated, so what a file's name or a mesh's
 * numbers claim never becomes an allocation by itself: a directory (whose end ftell() puts at
 * LLONG_MAX on ext4), a device or a pipe is refused as not a file, and a request for more bytes
 * than the file holds (a glTF buffer's byteLength of -20 reads as 2^64 - 20) as too short. */
#ifndef VKRT_FILE_READ_H
#define VKRT_FILE_READ_H

#include <stddef.h>

#include "core.h"

typedef enum file_read_status {
    FILE_READ_OK,
    FILE_READ_CANNOT_OPEN,   /* fopen() failed; errno says why */
    FILE_READ_NOT_A_FILE,    /* a directory, device, pipe or socket */
    FILE_READ_TOO_SHORT,     /* holds fewer bytes than were asked for */
    FILE_READ_FAILED,        /* a read error; errno says why */
    FILE_READ_OUT_OF_MEMORY,
} file_read_status;

/* Reads the first `size` bytes of the regular file at path, or the whole file where size is 0,
 * into *out (free it with core_free; an empty file gives a block of its own) and the number of
 * bytes into *out_size. On failure *out is NULL and nothing is allocated; errno is kept from
 * the failing call for FILE_READ_CANNOT_OPEN and FILE_READ_FAILED. */
file_read_status file_read(core *c, const char *path, size_t size, void **out, size_t *out_size);

/* The status in words for a message, with strerror(saved_errno) where errno says why. */
const char *file_read_status_text(file_read_status status, int saved_errno);

#endif
