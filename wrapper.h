/* Bindgen input for the system Embree. build.rs defines PCBPT_EMBREE4 when it found
 * Embree 4 headers and prefers them; otherwise Embree 3 is used. */
#ifdef PCBPT_EMBREE4
#include <embree4/rtcore.h>
#else
#include <embree3/rtcore.h>
#endif
