#include "file_read.h"

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

file_read_status file_read(core *c, const char *path, size_t size, void **out, size_t *out_size)
{
    *out = NULL;
    *out_size = 0;
    FILE *f = fopen(path, "rb");
    if (!f) return FILE_READ_CANNOT_OPEN;
    struct stat st;
    file_read_status status = FILE_READ_OK;
    size_t want = 0;
    if (fstat(fileno(f), &st) != 0) {
        status = FILE_READ_FAILED;
    } else if (!S_ISREG(st.st_mode) || st.st_size < 0) {
        status = FILE_READ_NOT_A_FILE;
    } else if ((uintmax_t)st.st_size > SIZE_MAX || (size && size > (size_t)st.st_size)) {
        status = FILE_READ_TOO_SHORT;
    } else {
        want = size ? size : (size_t)st.st_size;
    }
    void *bytes = NULL;
    if (status == FILE_READ_OK && !(bytes = core_alloc(c, want))) status = FILE_READ_OUT_OF_MEMORY;
    /* The file may have shrunk since fstat(): a short read is the same as a short file. */
    if (status == FILE_READ_OK && fread(bytes, 1, want, f) != want)
        status = ferror(f) ? FILE_READ_FAILED : FILE_READ_TOO_SHORT;
    int saved_errno = errno;
    fclose(f);
    errno = saved_errno;
    if (status != FILE_READ_OK) {
        core_free(c, bytes);
        return status;
    }
    *out = bytes;
    *out_size = want;
    return FILE_READ_OK;
}

const char *file_read_status_text(file_read_status status, int saved_errno)
{
    switch (status) {
    case FILE_READ_OK: return "read";
    case FILE_READ_CANNOT_OPEN:
    case FILE_READ_FAILED: return saved_errno ? strerror(saved_errno) : "input/output error";
    case FILE_READ_NOT_A_FILE: return "not a regular file";
    case FILE_READ_TOO_SHORT: return "the file is shorter than the data it should hold";
    case FILE_READ_OUT_OF_MEMORY: return "out of memory";
    }
    return "unknown failure";
}
