// SPDX-License-Identifier: Apache-2.0
/* LD_PRELOADed into LinuxCNC's rtapi_app by run-linuxcnc.sh. rtapi_app
 * raises RLIMIT_RTPRIO to unlimited before it takes its POSIX real-time
 * path, and falls back to SCHED_OTHER when that fails. In a container
 * without CAP_SYS_RESOURCE the raise fails although root's CAP_SYS_NICE
 * already allows SCHED_FIFO at any priority (cyclictest and cpmd use it):
 * this reports that one raise as done and leaves every other call alone. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <sys/resource.h>

int setrlimit(__rlimit_resource_t resource, const struct rlimit* limit) {
  static int (*real)(__rlimit_resource_t, const struct rlimit*);
  if (!real) real = (int (*)(__rlimit_resource_t, const struct rlimit*))dlsym(RTLD_NEXT, "setrlimit");
  const int rc = real(resource, limit);
  return rc != 0 && resource == RLIMIT_RTPRIO ? 0 : rc;
}
