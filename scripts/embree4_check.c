/* Checks that the Embree 4 headers and library that scripts/embree4.sh assembled agree:
 * the library's build options that change struct layouts (instance arrays add
 * `instPrimID` to RTCHit and the query contexts; the instance level count sizes the
 * `instID` stacks; min-width adds a field to the query arguments) must match the headers'
 * rtcore_config.h, or hits would be written past the caller's structs. Intersects known
 * geometry (two triangle meshes and an instance) and checks distance, ids and
 * barycentrics, and that no byte after the last RTCHit field of the header's layout is
 * written. Exit status 0 when all checks pass; prints one line per check. */
#include <embree4/rtcore.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

static int failures = 0;
static int errors_seen = 0;
static char last_error[512];

static void on_error(void *user, enum RTCError code, const char *message)
{
  (void)user;
  errors_seen++;
  snprintf(last_error, sizeof last_error, "%d: %s", (int)code, message ? message : "");
}

static void check(int ok, const char *what)
{
  printf("%s %s\n", ok ? "ok  " : "FAIL", what);
  if (!ok) failures++;
}

static RTCGeometry quad(RTCDevice device, float z, float dx)
{
  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  float *v = (float *)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 4);
  const float vv[12] = {-1 + dx, -1, z, 1 + dx, -1, z, 1 + dx, 1, z, -1 + dx, 1, z};
  memcpy(v, vv, sizeof vv);
  unsigned *ix = (unsigned *)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), 2);
  const unsigned ii[6] = {0, 1, 2, 0, 2, 3};
  memcpy(ix, ii, sizeof ii);
  rtcCommitGeometry(g);
  return g;
}

/* Bytes of `p[from..to)` that differ from the fill byte. */
static int dirty(const void *p, size_t from, size_t to)
{
  const unsigned char *b = (const unsigned char *)p;
  int n = 0;
  for (size_t i = from; i < to; i++) n += b[i] != 0x5A;
  return n;
}

static void init_ray(struct RTCRay *r, float x, float y)
{
  r->org_x = x; r->org_y = y; r->org_z = 0; r->tnear = 0;
  r->dir_x = 0; r->dir_y = 0; r->dir_z = 1; r->time = 0;
  r->tfar = INFINITY; r->mask = ~0u; r->id = 0; r->flags = 0;
}

#if defined(RTC_GEOMETRY_INSTANCE_ARRAY)
#define HIT_END (offsetof(struct RTCHit, instPrimID) + sizeof(((struct RTCHit *)0)->instPrimID))
#else
#define HIT_END (offsetof(struct RTCHit, instID) + sizeof(((struct RTCHit *)0)->instID))
#endif

static void shoot(RTCScene scene, float x, float y, float t, unsigned geom, unsigned prim, float u, float v,
                  unsigned inst, unsigned inst_prim, const char *what)
{
  struct RTCRayHit rh[2];
  memset(rh, 0x5A, sizeof rh);
  init_ray(&rh[0].ray, x, y);
  rh[0].hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh[0].hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh[0].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
#if defined(RTC_GEOMETRY_INSTANCE_ARRAY)
  rh[0].hit.instPrimID[0] = RTC_INVALID_GEOMETRY_ID;
#endif
  rtcIntersect1(scene, &rh[0], NULL);
  const struct RTCHit *h = &rh[0].hit;
  unsigned got_inst_prim = inst_prim;
#if defined(RTC_GEOMETRY_INSTANCE_ARRAY)
  got_inst_prim = h->instPrimID[0];
#endif
  char line[400];
  snprintf(line, sizeof line,
           "%s: t %g geomID %u primID %u u %g v %g instID %d instPrimID %d "
           "(expected t %g, %u, %u, %g, %g, %d, %d)",
           what, rh[0].ray.tfar, h->geomID, h->primID, h->u, h->v, (int)h->instID[0], (int)got_inst_prim, t, geom,
           prim, u, v, (int)inst, (int)inst_prim);
  check(fabsf(rh[0].ray.tfar - t) < 1e-5f && h->geomID == geom && h->primID == prim && fabsf(h->u - u) < 1e-5f &&
            fabsf(h->v - v) < 1e-5f && h->instID[0] == inst && got_inst_prim == inst_prim,
        line);
  const size_t hit_at = offsetof(struct RTCRayHit, hit);
  snprintf(line, sizeof line, "%s: no byte written after the header's RTCHit fields (%d padding, %d next struct)",
           what, dirty(&rh[0], hit_at + HIT_END, sizeof rh[0]), dirty(&rh[1], 0, sizeof rh[1]));
  check(dirty(&rh[0], hit_at + HIT_END, sizeof rh[0]) == 0 && dirty(&rh[1], 0, sizeof rh[1]) == 0, line);

  struct RTCRay ray[2];
  memset(ray, 0x5A, sizeof ray);
  init_ray(&ray[0], x, y);
  rtcOccluded1(scene, &ray[0], NULL);
  snprintf(line, sizeof line, "%s: occluded (tfar %g), nothing written after the RTCRay", what, ray[0].tfar);
  check(ray[0].tfar == -INFINITY && dirty(&ray[1], 0, sizeof ray[1]) == 0, line);
}

int main(void)
{
  RTCDevice device = rtcNewDevice("verbose=0");
  if (!device) {
    printf("FAIL rtcNewDevice returned null (error %d)\n", (int)rtcGetDeviceError(NULL));
    return 1;
  }
  rtcSetDeviceErrorFunction(device, on_error, NULL);
  long version = (long)rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_VERSION);
  printf("library version %ld, headers %d\n", version, RTC_VERSION);
  check(rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_VERSION_MAJOR) == 4, "library is Embree 4");

  /* Instance arrays (geometry type 122 since Embree 4.3): compiled in exactly when the
   * headers define RTC_GEOMETRY_INSTANCE_ARRAY. */
  errors_seen = 0;
  RTCGeometry array = rtcNewGeometry(device, (enum RTCGeometryType)122);
  int lib_arrays = array != NULL && errors_seen == 0;
  if (array) rtcReleaseGeometry(array);
#if defined(RTC_GEOMETRY_INSTANCE_ARRAY)
  int hdr_arrays = 1;
#else
  int hdr_arrays = 0;
#endif
  printf("library instance arrays: %s; headers RTC_GEOMETRY_INSTANCE_ARRAY: %s\n", lib_arrays ? "yes" : "no",
         hdr_arrays ? "defined" : "undefined");
  check(lib_arrays == hdr_arrays, "instance-array setting (RTCHit.instPrimID) matches");

  /* Min-width: rtcSetGeometryMaxRadiusScale fails when the library lacks it. */
  RTCGeometry sphere = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_SPHERE_POINT);
  errors_seen = 0;
  rtcSetGeometryMaxRadiusScale(sphere, 2.0f);
  int lib_min_width = errors_seen == 0;
  rtcReleaseGeometry(sphere);
  printf("library min-width: %s; headers RTC_MIN_WIDTH %d\n", lib_min_width ? "yes" : "no", RTC_MIN_WIDTH);
  check(lib_min_width == (RTC_MIN_WIDTH != 0), "min-width setting (query argument size) matches");
  errors_seen = 0;

  /* Two meshes (geometry 1 in front of geometry 0) and, at x = 10, an instance
   * (geometry 2) of a scene holding one mesh at z = 3. */
  RTCScene inner = rtcNewScene(device);
  RTCGeometry g = quad(device, 3.0f, 0.0f);
  rtcAttachGeometryByID(inner, g, 0);
  rtcReleaseGeometry(g);
  rtcCommitScene(inner);

  RTCScene scene = rtcNewScene(device);
  g = quad(device, 5.0f, 0.0f);
  rtcAttachGeometryByID(scene, g, 0);
  rtcReleaseGeometry(g);
  g = quad(device, 2.0f, 0.0f);
  rtcAttachGeometryByID(scene, g, 1);
  rtcReleaseGeometry(g);
  g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
  rtcSetGeometryInstancedScene(g, inner);
  const float xfm[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 10, 0, 0}; /* column major 3x4 */
  rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm);
  rtcCommitGeometry(g);
  rtcAttachGeometryByID(scene, g, 2);
  rtcReleaseGeometry(g);
  rtcCommitScene(scene);
  if (errors_seen) printf("FAIL embree error: %s\n", last_error), failures++;

  const unsigned none = RTC_INVALID_GEOMETRY_ID;
  /* (-0.5, 0.25) lies in triangle 1 (vertices 0, 2, 3): p = v0 + u (v2 - v0) + v (v3 - v0). */
  shoot(scene, -0.5f, 0.25f, 2.0f, 1, 1, 0.25f, 0.375f, none, none, "mesh hit");
  /* (0.5, -0.5) lies in triangle 0 (vertices 0, 1, 2). */
  shoot(scene, 0.5f, -0.5f, 2.0f, 1, 0, 0.5f, 0.25f, none, none, "mesh hit, triangle 0");
  /* The instance: the inner geometry's id, the instance's id on the stack, element 0. */
  shoot(scene, 10.5f, -0.5f, 3.0f, 0, 0, 0.5f, 0.25f, 2, 0, "instance hit");

  rtcReleaseScene(scene);
  rtcReleaseScene(inner);
  rtcReleaseDevice(device);
  printf("%d check(s) failed\n", failures);
  return failures != 0;
}
