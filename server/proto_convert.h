// Protobuf <-> engine types for the services: dtypes, array refs and infos, commands, devices,
// module sources, diagnostics.
#pragma once

#include "engine/core/module_source.h"
#include "engine/runtime/commands.h"
#include "engine/runtime/engine.h"
#include "weft/v1/array.pb.h"
#include "weft/v1/device.pb.h"
#include "weft/v1/exec.pb.h"
#include "weft/v1/geometry.pb.h"
#include "weft/v1/module.pb.h"
#include "weft/v1/types.pb.h"

namespace weft::server {

DType FromProto(const v1::DType& p);
void ToProto(const DType& d, v1::DType* p);
ArrayRef FromProto(const v1::ArrayRef& p);
void ToProto(const ArrayDesc& d, v1::ArrayInfo* p);
SourceLocation FromProto(const v1::SourceLocation& p);
void ToProto(const SourceLocation& l, v1::SourceLocation* p);
void ToProto(const Diagnostic& d, v1::Diagnostic* p);
void ToProto(const DeviceInfo& d, v1::DeviceInfo* p);
ModuleSource FromProto(const v1::ModuleSource& p);
// Fails on an empty oneof (INVALID_ARGUMENT naming the command index).
Expected<Command> FromProto(const v1::Command& p, size_t index);
// A geometry request: the op checked (1..8), the sizes of the volume fields bounded.
Expected<geometry::GeometryRequest> FromProto(const v1::GeometryRequest& p);

}  // namespace weft::server
