// DeviceService: the devices this daemon owns and the CUDA toolchain it runs with.
#include "engine/runtime/device_info.h"
#include "server/grpc_status.h"
#include "server/proto_convert.h"
#include "server/services.h"

namespace weft::server {

grpc::Status DeviceServiceImpl::List(grpc::ServerContext* ctx, const v1::ListDevicesRequest*,
                                     v1::ListDevicesResponse* resp) {
  Status st = auth_.Authenticate(*ctx);
  if (!st.ok()) return ToGrpc(st);
  for (const auto& d : auth_.engine().ListDevices()) ToProto(d, resp->add_devices());
  static const CudaToolchainInfo toolchain = QueryCudaToolchain();   // fixed for the process
  resp->set_cuda_driver_version(toolchain.driver_version);
  resp->set_nvrtc_version(toolchain.nvrtc_version);
  for (int32_t arch : toolchain.archs) resp->add_cuda_archs(arch);
  return grpc::Status::OK;
}

}  // namespace weft::server
