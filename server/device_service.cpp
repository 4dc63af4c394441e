// DeviceService: the devices this daemon owns.
#include "server/grpc_status.h"
#include "server/proto_convert.h"
#include "server/services.h"

namespace weft::server {

grpc::Status DeviceServiceImpl::List(grpc::ServerContext* ctx, const v1::ListDevicesRequest*,
                                     v1::ListDevicesResponse* resp) {
  Status st = auth_.Authenticate(*ctx);
  if (!st.ok()) return ToGrpc(st);
  for (const auto& d : auth_.engine().ListDevices()) ToProto(d, resp->add_devices());
  return grpc::Status::OK;
}

}  // namespace weft::server
