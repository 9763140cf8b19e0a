// tinybvh on one ray file, for benchmarks/tinybvh.py (which compiles and runs this program).
//
// Builds tinybvh's BVH_GPU (the Aila-Laine layout: 64-byte nodes that hold their children's boxes)
// over a triangle soup, and times tinybvh's own OpenCL traversal on the rays with profiling events:
// its closest-hit kernel, batch_ailalaine, and its occlusion walk, isoccluded_ailalaine (tinybvh
// has it as a function only; the one-line kernel around it below is ours). The kernel source and
// the build options are tinybvh's own (tiny_ocl.h's), so the figures are what tinybvh's speed test
// would show for these rays. The tinybvh sources are fetched by `python -m benchmarks.tinybvh fetch`
// and never committed.
//
// usage: tinybvh_driver SOURCES TRIANGLES RAYS DEVICE REPEAT WARMUP BUILDS OUT
//   SOURCES    folder holding tiny_bvh.h, traverse.cl and traverse_bvh2.cl
//   TRIANGLES  float32, 12 per triangle: three vertices as x y z 0 (tinybvh's bvhvec4 soup)
//   RAYS       float32, 6 per ray: origin, unit direction (benchmarks/raysets.py's ray file)
//   DEVICE     gpu or cpu: the first OpenCL device of that type, over all platforms
//   BUILDS     comma-separated: sah (BVH_GPU::Build, tinybvh's default binned SAH builder),
//              hq (BVH_GPU::BuildHQ, its SBVH with spatial splits)
//   OUT        folder for the answers: BUILD-closest.f32 (t u v prim, 4 x 32 bits per ray; t = 1e30
//              on a miss) and BUILD-any.u32 (1 where the ray meets any triangle)
// Prints "device: ..." and one line per build and query:
//   result BUILD QUERY BUILD_MS HITS MS,MS,...   (kernel ms of each timed launch)

#define TINYBVH_IMPLEMENTATION
#include "tiny_bvh.h"

#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using tinybvh::bvhvec3;
using tinybvh::bvhvec4;

static const size_t GROUP = 64;      // tinybvh's speed test launches its kernels in groups of 64
static const size_t RAY_BYTES = 64;  // traverse.cl's struct Ray: float4 O, D, rD, hit

static void fail(const std::string& message)
{
	fprintf(stderr, "tinybvh driver: %s\n", message.c_str());
	exit(1);
}

static void check(cl_int error, const char* what)
{
	if (error != CL_SUCCESS) fail(std::string(what) + " failed (OpenCL error " + std::to_string(error) + ")");
}

static std::string read_text(const std::string& path)
{
	std::ifstream file(path, std::ios::binary);
	if (!file) fail("cannot read " + path);
	std::stringstream text;
	text << file.rdbuf();
	return text.str();
}

static std::vector<float> read_floats(const std::string& path, size_t per_row)
{
	std::string bytes = read_text(path);
	if (bytes.empty() || bytes.size() % (4 * per_row))
		fail(path + ": not rows of " + std::to_string(per_row) + " float32");
	std::vector<float> values(bytes.size() / 4);
	memcpy(values.data(), bytes.data(), bytes.size());
	return values;
}

static void write_bytes(const std::string& path, const void* data, size_t size)
{
	std::ofstream file(path, std::ios::binary);
	file.write((const char*)data, size);
	if (!file) fail("cannot write " + path);
}

// traverse.cl with the one file it includes that this driver runs, traverse_bvh2.cl (the Aila-Laine
// walks), expanded on the host as tiny_ocl.h does for some drivers. The other layouts' walks are left
// out: unused here, and on PoCL's CPU device (whose name says AMD here, so tiny_ocl.h's AMD switches
// apply) the CWBVH walk casts global pointers to private ones, which PoCL refuses to build.
static std::string kernel_source(const std::string& folder)
{
	std::string text = read_text(folder + "/traverse.cl");
	for (size_t at; (at = text.find("#include \"")) != std::string::npos;)
	{
		const size_t start = at + 10, end = text.find('"', start);
		if (end == std::string::npos) fail("traverse.cl: an #include without its closing quote");
		const std::string name = text.substr(start, end - start);
		const std::string body = name == "traverse_bvh2.cl" ? read_text(folder + "/" + name) + "\n" : "";
		text = text.substr(0, at) + body + text.substr(end + 1);
	}
	if (text.find("batch_ailalaine") == std::string::npos) fail("traverse.cl no longer includes traverse_bvh2.cl");
	return text;
}

// The occlusion query: tinybvh's isoccluded_ailalaine on each ray, no opacity map, no distance limit.
static const char* OCCLUSION_KERNEL = R"(
void kernel driver_isoccluded( const global struct BVHNode* bvhNode, const global uint* idx,
	const global float4* verts, const global struct Ray* rayData, global uint* occluded )
{
	const uint i = get_global_id( 0 );
	const float3 O = rayData[i].O.xyz, D = rayData[i].D.xyz, rD = rayData[i].rD.xyz;   // as batch_ailalaine reads them
	occluded[i] = isoccluded_ailalaine( bvhNode, idx, verts, 0, O, D, rD, 1e30f ) ? 1 : 0;
}
)";

static std::string device_text(cl_device_id device, cl_device_info what)
{
	char text[1024] = {};
	clGetDeviceInfo(device, what, sizeof(text) - 1, text, 0);
	return text;
}

static cl_device_id pick_device(const std::string& kind)
{
	const cl_device_type type = kind == "gpu" ? CL_DEVICE_TYPE_GPU : CL_DEVICE_TYPE_CPU;
	cl_uint platforms = 0;
	clGetPlatformIDs(0, 0, &platforms);
	std::vector<cl_platform_id> ids(platforms);
	if (platforms) clGetPlatformIDs(platforms, ids.data(), 0);
	for (cl_platform_id platform : ids)
	{
		cl_device_id device;
		cl_uint found = 0;
		if (clGetDeviceIDs(platform, type, 1, &device, &found) == CL_SUCCESS && found) return device;
	}
	fail("no OpenCL " + kind + " device (" + std::to_string(platforms) + " platforms)");
	return 0;
}

// tiny_ocl.h's vendor define (from the device's name, lower case, as tiny_ocl.h reads it) and its
// build options, so that tinybvh's kernel is built as tinybvh builds it.
static std::string vendor_define(std::string name)
{
	for (char& c : name) c = (char)tolower((unsigned char)c);
	if (name.find("nvidia") != std::string::npos) return "#define ISNVIDIA\n";
	for (const char* amd : {"amd", "ellesmere", "rdna", "gfx11", "gfx10", "gfx9", "gfx8"})
		if (name.find(amd) != std::string::npos) return "#define ISAMD\n";
	if (name.find("intel") != std::string::npos) return "#define ISINTEL\n";
	if (name.find("apple") != std::string::npos) return "#define ISAPPLE\n";
	return "#define ISOTHER\n";
}

static double launch(cl_command_queue queue, cl_kernel kernel, size_t count)
{
	cl_event event;
	check(clEnqueueNDRangeKernel(queue, kernel, 1, 0, &count, &GROUP, 0, 0, &event), "clEnqueueNDRangeKernel");
	check(clWaitForEvents(1, &event), "clWaitForEvents");
	cl_ulong start = 0, end = 0;
	clGetEventProfilingInfo(event, CL_PROFILING_COMMAND_START, sizeof(start), &start, 0);
	clGetEventProfilingInfo(event, CL_PROFILING_COMMAND_END, sizeof(end), &end, 0);
	clReleaseEvent(event);
	return 1e-6 * (double)(end - start);
}

static std::vector<double> time_kernel(cl_command_queue queue, cl_kernel kernel, size_t count, int repeat, int warmup)
{
	std::vector<double> ms;
	for (int i = 0; i < warmup + repeat; i++)
	{
		const double took = launch(queue, kernel, count);
		if (i >= warmup) ms.push_back(took);
	}
	return ms;
}

static std::string joined(const std::vector<double>& ms)
{
	std::string text;
	char number[32];
	for (size_t i = 0; i < ms.size(); i++)
		snprintf(number, sizeof(number), i ? ",%.6f" : "%.6f", ms[i]), text += number;
	return text;
}

int main(int argc, char** argv)
{
	if (argc != 9) fail("usage: tinybvh_driver SOURCES TRIANGLES RAYS DEVICE REPEAT WARMUP BUILDS OUT");
	const std::string sources = argv[1], device_kind = argv[4], builds = argv[7], out = argv[8];
	const int repeat = atoi(argv[5]), warmup = atoi(argv[6]);
	if (device_kind != "gpu" && device_kind != "cpu") fail("DEVICE must be gpu or cpu");
	if (repeat < 1 || warmup < 0) fail("REPEAT must be at least 1 and WARMUP not negative");
	std::vector<float> soup = read_floats(argv[2], 12), rows = read_floats(argv[3], 6);
	const uint32_t triangles = (uint32_t)(soup.size() / 12);
	const size_t rays = rows.size() / 6, padded = (rays + GROUP - 1) / GROUP * GROUP;

	cl_device_id device = pick_device(device_kind);
	const std::string name = device_text(device, CL_DEVICE_NAME), define = vendor_define(name);
	printf("device: %s (%s; %s)\n", name.c_str(), device_text(device, CL_DEVICE_VERSION).c_str(),
		define.substr(8, define.size() - 9).c_str());
	cl_int error;
	cl_context context = clCreateContext(0, 1, &device, 0, 0, &error);
	check(error, "clCreateContext");
	cl_command_queue queue = clCreateCommandQueue(context, device, CL_QUEUE_PROFILING_ENABLE, &error);
	check(error, "clCreateCommandQueue");
	const std::string source = define + kernel_source(sources) + OCCLUSION_KERNEL;
	const char* text = source.c_str();
	cl_program program = clCreateProgramWithSource(context, 1, &text, 0, &error);
	check(error, "clCreateProgramWithSource");
	std::string options = "-cl-std=CL2.0 -cl-strict-aliasing -cl-fast-relaxed-math -cl-single-precision-constant";
	if (define == "#define ISNVIDIA\n") options += " -cl-nv-opt-level=9";
	if (clBuildProgram(program, 1, &device, options.c_str(), 0, 0) != CL_SUCCESS)
	{
		size_t size = 0;
		clGetProgramBuildInfo(program, device, CL_PROGRAM_BUILD_LOG, 0, 0, &size);
		std::string log(size, '\0');
		clGetProgramBuildInfo(program, device, CL_PROGRAM_BUILD_LOG, size, &log[0], 0);
		fail("tinybvh's traverse.cl did not build:\n" + log);
	}
	cl_kernel closest = clCreateKernel(program, "batch_ailalaine", &error);
	check(error, "clCreateKernel batch_ailalaine");
	cl_kernel occlusion = clCreateKernel(program, "driver_isoccluded", &error);
	check(error, "clCreateKernel driver_isoccluded");

	// The rays as traverse.cl's struct Ray, rD from tinybvh's own safe reciprocal (as its Ray constructor
	// makes it). The kernels take no ray count: the last group is filled with copies of the first ray.
	std::vector<float> ray_data(padded * RAY_BYTES / 4, 0.0f);
	for (size_t i = 0; i < padded; i++)
	{
		const float* row = &rows[6 * (i < rays ? i : 0)];
		const bvhvec3 D(row[3], row[4], row[5]), rD = tinybvh::tinybvh_rcp(D);
		float* ray = &ray_data[16 * i];
		ray[0] = row[0], ray[1] = row[1], ray[2] = row[2];
		ray[4] = D.x, ray[5] = D.y, ray[6] = D.z;
		ray[8] = rD.x, ray[9] = rD.y, ray[10] = rD.z;
	}
	cl_mem ray_buffer = clCreateBuffer(context, CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, ray_data.size() * 4,
		ray_data.data(), &error);
	check(error, "clCreateBuffer rays");
	cl_mem vert_buffer = clCreateBuffer(context, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, soup.size() * 4,
		soup.data(), &error);
	check(error, "clCreateBuffer triangles");
	cl_mem occluded_buffer = clCreateBuffer(context, CL_MEM_WRITE_ONLY, padded * 4, 0, &error);
	check(error, "clCreateBuffer occluded");

	std::stringstream names(builds);
	for (std::string build; std::getline(names, build, ',');)
	{
		if (build != "sah" && build != "hq") fail("unknown build " + build + " (sah or hq)");
		tinybvh::BVH_GPU bvh;
		const auto start = std::chrono::steady_clock::now();
		if (build == "sah") bvh.Build((const bvhvec4*)soup.data(), triangles);
		else bvh.BuildHQ((const bvhvec4*)soup.data(), triangles);
		const double build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
		cl_mem nodes = clCreateBuffer(context, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
			bvh.usedNodes * sizeof(tinybvh::BVH_GPU::BVHNode), bvh.bvhNode, &error);
		check(error, "clCreateBuffer nodes");
		cl_mem indices = clCreateBuffer(context, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
			bvh.idxCount * sizeof(uint32_t), bvh.bvh.primIdx, &error);
		check(error, "clCreateBuffer indices");
		for (cl_kernel kernel : {closest, occlusion})
		{
			clSetKernelArg(kernel, 0, sizeof(cl_mem), &nodes);
			clSetKernelArg(kernel, 1, sizeof(cl_mem), &indices);
			clSetKernelArg(kernel, 2, sizeof(cl_mem), &vert_buffer);
			clSetKernelArg(kernel, 3, sizeof(cl_mem), &ray_buffer);
		}
		clSetKernelArg(occlusion, 4, sizeof(cl_mem), &occluded_buffer);

		std::vector<double> ms = time_kernel(queue, closest, padded, repeat, warmup);
		std::vector<float> answers(padded * RAY_BYTES / 4);
		check(clEnqueueReadBuffer(queue, ray_buffer, CL_TRUE, 0, answers.size() * 4, answers.data(), 0, 0, 0), "read rays");
		std::vector<float> hits(4 * rays);
		size_t count = 0;
		for (size_t i = 0; i < rays; i++)
		{
			memcpy(&hits[4 * i], &answers[16 * i + 12], 16);   // struct Ray's hit: t u v prim
			count += hits[4 * i] < 1e30f;
		}
		write_bytes(out + "/" + build + "-closest.f32", hits.data(), hits.size() * 4);
		printf("result %s closest %.3f %zu %s\n", build.c_str(), build_ms, count, joined(ms).c_str());

		ms = time_kernel(queue, occlusion, padded, repeat, warmup);
		std::vector<uint32_t> occluded(padded);
		check(clEnqueueReadBuffer(queue, occluded_buffer, CL_TRUE, 0, padded * 4, occluded.data(), 0, 0, 0), "read occluded");
		count = 0;
		for (size_t i = 0; i < rays; i++) count += occluded[i] != 0;
		write_bytes(out + "/" + build + "-any.u32", occluded.data(), rays * 4);
		printf("result %s any %.3f %zu %s\n", build.c_str(), build_ms, count, joined(ms).c_str());
		fflush(stdout);
		clReleaseMemObject(nodes);
		clReleaseMemObject(indices);
	}
	return 0;
}
