// ArrayService: create/free/describe, chunked read/write, IPC export/import, CUDA IPC import of
// the client's GPU memory.
#include <spdlog/spdlog.h>

#include "server/grpc_status.h"
#include "server/proto_convert.h"
#include "server/services.h"

namespace weft::server {

namespace {
grpc::Status Fail(const grpc::ServerContext* ctx, const char* what, const Status& st) {
  spdlog::info("{} from {} failed: {}", what, ctx->peer(), st.ToString());
  return ToGrpc(st);
}
}  // namespace

Status ArrayCreate(Engine& engine, Session& s, const v1::CreateArrayRequest& req, v1::CreateArrayResponse* resp) {
  CreateArrayParams p;
  p.dtype = FromProto(req.dtype());
  p.shape.assign(req.shape().begin(), req.shape().end());
  p.device = req.device().empty() ? "cpu" : req.device();
  p.requires_grad = req.requires_grad();
  p.pinned = req.pinned();
  p.init = static_cast<CreateArrayParams::Init>(req.init());
  p.value = req.value();
  auto r = engine.CreateArray(s, p);
  if (!r.ok()) return r.status();
  ToProto(*r, resp->mutable_info());
  if (r->grad_handle != 0) {
    auto g = engine.DescribeArray(s, r->grad_handle);
    if (g.ok()) ToProto(*g, resp->mutable_grad_info());
  }
  return Status::Ok();
}

Status ArrayFree(Engine& engine, Session& s, const v1::FreeArrayRequest& req) {
  if (req.handles().empty()) return engine.FreeArray(s, req.handle());
  if (req.handles_size() > kMaxFreeHandles)
    return InvalidArgument("array free: " + std::to_string(req.handles_size()) + " handles in one request (at most " +
                           std::to_string(kMaxFreeHandles) + ")");
  Status first = req.handle() != 0 ? engine.FreeArray(s, req.handle()) : Status::Ok();
  for (uint64_t h : req.handles()) {
    Status st = engine.FreeArray(s, h);
    if (first.ok() && !st.ok()) first = st;
  }
  return first;
}

Status ArrayImportCuda(Engine& engine, Session& s, const v1::ImportCudaRequest& req, v1::ImportCudaResponse* resp) {
  CudaImportParams p;
  p.device = req.device();
  p.dtype = FromProto(req.dtype());
  p.shape.assign(req.shape().begin(), req.shape().end());
  p.data = {req.data().ipc_handle(), req.data().allocation_id(), req.data().byte_offset()};
  p.has_grad = req.has_grad();
  if (p.has_grad) p.grad = {req.grad().ipc_handle(), req.grad().allocation_id(), req.grad().byte_offset()};
  auto r = engine.ImportCudaArray(s, p);
  if (!r.ok()) return r.status();
  ToProto(*r, resp->mutable_info());
  return Status::Ok();
}

Status ArrayDescribe(Engine& engine, Session& s, const v1::DescribeArrayRequest& req, v1::DescribeArrayResponse* resp) {
  auto r = engine.DescribeArray(s, req.handle());
  if (!r.ok()) return r.status();
  ToProto(*r, resp->mutable_info());
  return Status::Ok();
}

grpc::Status ArrayServiceImpl::Create(grpc::ServerContext* ctx, const v1::CreateArrayRequest* req,
                                      v1::CreateArrayResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  Status st = ArrayCreate(auth_.engine(), **s, *req, resp);
  if (!st.ok()) return Fail(ctx, "array create", st);
  return grpc::Status::OK;
}

grpc::Status ArrayServiceImpl::Free(grpc::ServerContext* ctx, const v1::FreeArrayRequest* req, v1::FreeArrayResponse*) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  Status st = ArrayFree(auth_.engine(), **s, *req);
  if (!st.ok()) return Fail(ctx, "array free", st);
  return grpc::Status::OK;
}

grpc::Status ArrayServiceImpl::Describe(grpc::ServerContext* ctx, const v1::DescribeArrayRequest* req,
                                        v1::DescribeArrayResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  Status st = ArrayDescribe(auth_.engine(), **s, *req, resp);
  if (!st.ok()) return Fail(ctx, "array describe", st);
  return grpc::Status::OK;
}

grpc::Status ArrayServiceImpl::Read(grpc::ServerContext* ctx, const v1::ReadArrayRequest* req,
                                    grpc::ServerWriter<v1::ArrayChunk>* writer) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  uint32_t chunk = req->chunk_size();
  if (chunk == 0 || chunk > (16u << 20)) chunk = chunk == 0 ? (1u << 20) : (16u << 20);
  v1::ArrayChunk msg;
  Status st = auth_.engine().ReadArray(**s, req->handle(), req->byte_offset(), req->byte_count(), chunk,
                                       [&](uint64_t off, const char* data, size_t n) {
                                         if (ctx->IsCancelled()) return false;
                                         msg.set_byte_offset(off);
                                         msg.set_data(data, n);
                                         return writer->Write(msg);
                                       });
  if (!st.ok()) return Fail(ctx, "array read", st);
  return grpc::Status::OK;
}

grpc::Status ArrayServiceImpl::Write(grpc::ServerContext* ctx, grpc::ServerReader<v1::WriteArrayRequest>* reader,
                                     v1::WriteArrayResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  v1::WriteArrayRequest msg;
  uint64_t handle = 0, written = 0;
  bool first = true;
  while (reader->Read(&msg)) {
    if (first) {
      handle = msg.handle();
      first = false;
      if (handle == 0) return ToGrpc(InvalidArgument("array write: the first message must carry the handle"));
    } else if (msg.handle() != 0 && msg.handle() != handle) {
      return ToGrpc(InvalidArgument("array write: one stream writes one array (got handles " + std::to_string(handle) +
                                    " and " + std::to_string(msg.handle()) + ")"));
    }
    if (!msg.has_chunk()) continue;
    const std::string& data = msg.chunk().data();
    Status st = auth_.engine().WriteArray(**s, handle, msg.chunk().byte_offset(), data.data(), data.size());
    if (!st.ok()) return Fail(ctx, "array write", st);
    written += data.size();
  }
  if (first) return ToGrpc(InvalidArgument("array write: empty stream (no handle)"));
  resp->set_bytes_written(written);
  return grpc::Status::OK;
}

grpc::Status ArrayServiceImpl::Export(grpc::ServerContext* ctx, const v1::ExportArrayRequest* req,
                                      v1::ExportArrayResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  auto r = auth_.engine().ExportArray(**s, req->handle());
  if (!r.ok()) return Fail(ctx, "array export", r.status());
  resp->set_token(*r);
  return grpc::Status::OK;
}

grpc::Status ArrayServiceImpl::Import(grpc::ServerContext* ctx, const v1::ImportArrayRequest* req,
                                      v1::ImportArrayResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  auto r = auth_.engine().ImportArray(**s, req->token());
  if (!r.ok()) return Fail(ctx, "array import", r.status());
  ToProto(*r, resp->mutable_info());
  return grpc::Status::OK;
}

grpc::Status ArrayServiceImpl::ImportCuda(grpc::ServerContext* ctx, const v1::ImportCudaRequest* req,
                                          v1::ImportCudaResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  Status st = ArrayImportCuda(auth_.engine(), **s, *req, resp);
  if (!st.ok()) return Fail(ctx, "CUDA import", st);
  return grpc::Status::OK;
}

}  // namespace weft::server
