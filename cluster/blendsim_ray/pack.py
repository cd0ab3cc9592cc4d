"""The files a task carries: a scene's inputs packed on the driver, a bake's output folder
packed on the worker. Plain (uncompressed) tar in memory: the files are placed by their paths
relative to a root, so a scene's relative paths (`../../assets/x.obj`) resolve the same on
the worker as on the driver."""

import io
import os
import tarfile


def pack_inputs(scene, inputs, cwd):
    """Tar the `inputs` (paths as `blendsim inputs` printed them, relative to `cwd` or absolute)
    under their common root with `cwd`. Returns (tar bytes, the worker's working folder
    relative to the root, the scene's path relative to it)."""
    absolute = [os.path.normpath(os.path.join(cwd, p)) for p in inputs]
    root = os.path.commonpath([cwd] + absolute)
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for given, path in zip(inputs, absolute):
            # Read as the bake reads it (through any symlink), placed by its lexical path.
            info = tar.gettarinfo(os.path.join(cwd, given), arcname=os.path.relpath(path, root))
            info.uid = info.gid = 0
            info.uname = info.gname = ""
            with open(os.path.join(cwd, given), "rb") as f:
                tar.addfile(info, f)
    scene_arg = os.path.relpath(os.path.normpath(os.path.join(cwd, scene)), cwd) if os.path.isabs(scene) else scene
    return buffer.getvalue(), os.path.relpath(cwd, root), scene_arg


def pack_folder(folder):
    """Tar every file of a bake's output folder (its manifest included), by name."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.PAX_FORMAT) as tar:
        for name in sorted(os.listdir(folder)):
            tar.add(os.path.join(folder, name), arcname=name, recursive=False)
    return buffer.getvalue()


def unpack(data, folder):
    """Extract a tar made by this module into `folder` (plain files and folders only)."""
    os.makedirs(folder, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r") as tar:
        tar.extractall(folder, filter="data")
