// Conversions between the client's plain types and the weft.v1 protobuf messages.
#pragma once

#include "weft/client/commands.h"
#include "weft/client/types.h"
#include "weft/v1/device.pb.h"
#include "weft/v1/exec.pb.h"
#include "weft/v1/session.pb.h"
#include "weft/v1/types.pb.h"

namespace weft::inline client_v1::detail {

void ToProto(const DType& in, v1::DType* out);
DType FromProto(const v1::DType& in);
ArrayInfo FromProto(const v1::ArrayInfo& in);
DeviceInfo FromProto(const v1::DeviceInfo& in);
DaemonStats FromProto(const v1::StatsResponse& in);
void ToProto(const ArrayView& in, v1::ArrayRef* out);
void ToProto(const KernelArg& in, v1::ArgValue* out);
void ToProto(const Command& in, v1::Command* out);

}  // namespace weft::client_v1::detail
