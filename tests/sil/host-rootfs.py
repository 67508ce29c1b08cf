#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""The systemd guest's root file system from this host's own installed Debian packages.

The host runs Debian bookworm and has every package the guest needs installed
(the build's dependencies pull in the libraries cpmd links). Instead of
downloading and unpacking them again (mmdebstrap, 3-4 min on a loaded host),
copy their files as dpkg installed them here: the packages are the Essential
ones, systemd, systemd-sysv, iproute2 and the .deb's Depends, with their
Pre-Depends and Depends closed over; the files are each package's dpkg list;
the dpkg database holds exactly those packages, so that dpkg -i in the guest
checks the .deb's Depends against them.

  host-rootfs.py list PACKAGE...       the closure, "name version" a line (the image's key)
  host-rootfs.py copy ROOT PACKAGE...  copy the closure's files and dpkg database into ROOT

Left out as mmdebstrap's recipe leaves them out: documentation, man pages,
locales (copyright files stay). Users and groups are the host's system ones
(uid < 1000) without cpmd, whom the guest's dpkg -i must create.
"""
import os
import shutil
import stat
import sys

STATUS = "/var/lib/dpkg/status"
INFO = "/var/lib/dpkg/info"
EXCLUDE = ("/usr/share/doc/", "/usr/share/man/", "/usr/share/locale/", "/usr/share/info/")


def fail(msg):
    print(f"host-rootfs: error: {msg}", file=sys.stderr)
    sys.exit(1)


def read_status():
    """Installed packages: name -> paragraph (dict, with its raw text)."""
    pkgs = {}
    with open(STATUS, encoding="utf-8") as f:
        for block in f.read().split("\n\n"):
            fields, key = {}, None
            for line in block.splitlines():
                if line[:1] in (" ", "\t") and key:
                    fields[key] += "\n" + line
                elif ":" in line:
                    key, _, value = line.partition(":")
                    fields[key] = value.strip()
            if fields.get("Status", "").endswith(" installed") and "Package" in fields:
                fields["_raw"] = block.strip("\n")
                pkgs[fields["Package"]] = fields
    return pkgs


def closure(pkgs, roots):
    provides = {}
    for name, p in pkgs.items():
        for alt in p.get("Provides", "").split(","):
            alt = alt.split("(")[0].strip()
            if alt:
                provides.setdefault(alt, name)
    want, todo = set(), list(roots)
    for name, p in pkgs.items():
        if p.get("Essential") == "yes":
            todo.append(name)
    while todo:
        name = todo.pop()
        if name in want:
            continue
        if name not in pkgs:
            fail(f"package {name} is not installed on this host (tools/setup.sh; or CPM_SIL_ROOTFS=mmdebstrap)")
        want.add(name)
        p = pkgs[name]
        deps = ",".join(x for x in (p.get("Pre-Depends", ""), p.get("Depends", "")) if x)
        for group in deps.split(","):
            group = group.strip()
            if not group:
                continue
            chosen = None
            for alt in group.split("|"):
                alt = alt.split("(")[0].split(":")[0].strip()
                if alt in pkgs:
                    chosen = alt
                    break
                if alt in provides:
                    chosen = provides[alt]
                    break
            if chosen is None:
                fail(f"{name} depends on '{group}', which nothing installed here satisfies")
            todo.append(chosen)
    return sorted(want)


def info_prefix(p):
    name = p["Package"]
    if p.get("Multi-Arch") == "same":
        return f"{name}:{p['Architecture']}"
    return name


def real_parent(path):
    """The path with its directory resolved (merged /usr: /bin/x is /usr/bin/x), its last part kept."""
    d, b = os.path.split(path)
    return os.path.join(os.path.realpath(d), b)


def copy_one(src, root):
    dst = root + src
    st = os.lstat(src)
    if stat.S_ISDIR(st.st_mode):
        os.makedirs(dst, exist_ok=True)
        shutil.copystat(src, dst, follow_symlinks=False)
        os.chown(dst, st.st_uid, st.st_gid)
        return
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    if os.path.lexists(dst):
        return
    if stat.S_ISLNK(st.st_mode):
        os.symlink(os.readlink(src), dst)
        os.lchown(dst, st.st_uid, st.st_gid)
    elif stat.S_ISREG(st.st_mode):
        shutil.copy2(src, dst)
        os.chown(dst, st.st_uid, st.st_gid)


def copy(root, pkgs, names):
    os.makedirs(root, exist_ok=True)
    # merged /usr, as bookworm's base-files and usrmerge leave it
    for d in ("bin", "sbin", "lib", "lib64"):
        os.makedirs(f"{root}/usr/{d}", exist_ok=True)
        if not os.path.lexists(f"{root}/{d}"):
            os.symlink(f"usr/{d}", f"{root}/{d}")
    for d in ("proc", "sys", "dev", "run", "tmp", "root", "var/tmp", "var/log", "var/lib/dpkg/info",
              "var/lib/dpkg/updates", "var/lib/dpkg/triggers", "var/lib/dpkg/alternatives", "etc/alternatives"):
        os.makedirs(f"{root}/{d}", exist_ok=True)
    os.chmod(f"{root}/tmp", 0o1777)
    os.chmod(f"{root}/var/tmp", 0o1777)
    os.chmod(f"{root}/root", 0o700)
    status = []
    for name in names:
        p = pkgs[name]
        prefix = info_prefix(p)
        listfile = f"{INFO}/{prefix}.list"
        if not os.path.exists(listfile):
            fail(f"no {listfile}")
        with open(listfile, encoding="utf-8") as f:
            for path in f.read().splitlines():
                if not path or path == "/." or (path.startswith(EXCLUDE) and not path.endswith("/copyright")):
                    continue
                src = real_parent(path)
                if os.path.lexists(src):
                    copy_one(src, root)
        for entry in os.listdir(INFO):
            if entry.startswith(prefix + "."):
                shutil.copy2(f"{INFO}/{entry}", f"{root}/var/lib/dpkg/info/{entry}")
        status.append(p["_raw"])
    with open(f"{root}/var/lib/dpkg/status", "w", encoding="utf-8") as f:
        f.write("\n\n".join(status) + "\n")
    for f in ("available", "diversions", "statoverride"):
        open(f"{root}/var/lib/dpkg/{f}", "a").close()
    # the alternatives whose chosen file was copied (update-alternatives' links,
    # in no dpkg list: /usr/bin/awk -> /etc/alternatives/awk -> /usr/bin/mawk),
    # the master link and its slaves as the host has them
    for alt in os.listdir("/var/lib/dpkg/alternatives"):
        link = f"/etc/alternatives/{alt}"
        if not (os.path.islink(link) and os.path.lexists(root + os.readlink(link))):
            continue
        shutil.copy2(f"/var/lib/dpkg/alternatives/{alt}", f"{root}/var/lib/dpkg/alternatives/{alt}")
        with open(f"/var/lib/dpkg/alternatives/{alt}", encoding="utf-8") as f:
            lines = f.read().split("\n")
        names = [(alt, lines[1])]
        i = 2
        while i + 1 < len(lines) and lines[i]:
            names.append((lines[i], lines[i + 1]))
            i += 2
        for name, path in names:
            target = f"/etc/alternatives/{name}"
            if not (os.path.islink(target) and os.path.lexists(root + os.readlink(target))):
                continue
            if not os.path.lexists(root + target):
                os.symlink(os.readlink(target), root + target)
            path = real_parent(path)
            if os.path.islink(path) and os.readlink(path) == target and not os.path.lexists(root + path):
                os.makedirs(os.path.dirname(root + path), exist_ok=True)
                os.symlink(target, root + path)
    # the host's system users and groups, without cpmd
    for f, mode in (("passwd", 0o644), ("group", 0o644), ("shadow", 0o640), ("gshadow", 0o640)):
        with open(f"/etc/{f}", encoding="utf-8") as src:
            lines = src.read().splitlines()
        keep = []
        for line in lines:
            parts = line.split(":")
            if parts[0] == "cpmd":
                continue
            if f in ("passwd", "group") and len(parts) > 2 and parts[2].isdigit() and 1000 <= int(parts[2]) < 65534:
                continue
            keep.append(line)
        names_kept = {line.split(":")[0] for line in keep}
        if f in ("shadow", "gshadow"):
            base = "passwd" if f == "shadow" else "group"
            with open(f"{root}/etc/{base}", encoding="utf-8") as b:
                allowed = {line.split(":")[0] for line in b.read().splitlines()}
            keep = [line for line in keep if line.split(":")[0] in allowed]
        del names_kept
        with open(f"{root}/etc/{f}", "w", encoding="utf-8") as dst:
            dst.write("\n".join(keep) + "\n")
        os.chmod(f"{root}/etc/{f}", mode)
        if f in ("shadow", "gshadow"):
            shadow_gid = next((int(line.split(":")[2]) for line in open(f"{root}/etc/group", encoding="utf-8")
                               if line.startswith("shadow:")), 0)
            os.chown(f"{root}/etc/{f}", 0, shadow_gid)
    open(f"{root}/etc/machine-id", "w").close()


def main():
    if len(sys.argv) < 3 or sys.argv[1] not in ("list", "copy"):
        fail("usage: host-rootfs.py list PACKAGE... | copy ROOT PACKAGE...")
    pkgs = read_status()
    if sys.argv[1] == "list":
        for name in closure(pkgs, sys.argv[2:]):
            print(name, pkgs[name].get("Version", ""))
        return
    root = os.path.abspath(sys.argv[2])
    names = closure(pkgs, sys.argv[3:])
    copy(root, pkgs, names)
    print(f"host-rootfs: {len(names)} packages copied into {root}")


if __name__ == "__main__":
    main()
