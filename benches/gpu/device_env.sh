# Sourced by device_check.sh and device_ab.sh on the device machine: unpacks what the call
# carried (the Vulkan loader's .deb files in .gl/, the gzipped builds in .devbin/), puts this
# tree's extension in place, points the loader at NVIDIA's driver and sets the GPU tests' switches.
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
for f in .devbin/*.gz; do gunzip -f "$f"; done; chmod +x .devbin/*
[ -f .devbin/_core.abi3.so ] && mv .devbin/_core.abi3.so python/physcore/
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
[ -f "$VK_DRIVER_FILES" ] || unset VK_DRIVER_FILES
export PYTHONPATH="$PWD/python" PYTHONUNBUFFERED=1 PHYSCORE_GPU_REQUIRED=1 PHYSCORE_GPU_ALLOW_CPU=1
