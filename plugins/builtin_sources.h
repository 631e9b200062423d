#pragma once
/// Registers every camera source built into this executable with
/// CameraSourceRegistry::Global(). Call once at start-up (idempotent).

namespace arpos {
void RegisterBuiltinCameraSources();
}  // namespace arpos
