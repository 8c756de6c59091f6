/**
* slamrun: DynaSLAM's numpy <-> cv::Mat conversion (src/Conversion.cc) for OpenCV >= 3, by copying.
*
* Upstream shares the buffer through a custom cv::MatAllocator. Its OpenCV 2.4 branch is the tested one; its
* OpenCV 3 branch stores a Python reference count in UMatData::refcount and later turns that field's address
* back into a PyObject*, which is not the object (the crashes DynaSLAM users report with OpenCV 3, issue #51).
* OpenCV 4 has only that branch. Here both directions copy the pixels instead (one 640x480 frame and one mask
* per call: microseconds against Mask R-CNN's seconds), and own nothing across the boundary.
* Same interface as upstream's (include/Conversion.h is unchanged).
*/

#include "Conversion.h"
#include <cstring>
#include <iostream>

namespace DynaSLAM
{

static int slamrun_fail(const char *what)
{
    PyErr_SetString(PyExc_TypeError, what);
    std::cerr << "DynaSLAM conversion: " << what << std::endl;
    return 0;
}

NDArrayConverter::NDArrayConverter() { init(); }

void NDArrayConverter::init()
{
    import_array();
}

cv::Mat NDArrayConverter::toMat(const PyObject *obj)
{
    PyObject *o = const_cast<PyObject *>(obj);
    if (!o || o == Py_None || !PyArray_Check(o))
    {
        slamrun_fail("toMat: not a numpy array");
        return cv::Mat();
    }
    int typenum = PyArray_TYPE((PyArrayObject *)o);
    int depth, target;
    switch (typenum)
    {
        case NPY_UBYTE: depth = CV_8U; target = NPY_UBYTE; break;
        case NPY_BOOL: depth = CV_8U; target = NPY_UBYTE; break;
        case NPY_BYTE: depth = CV_8S; target = NPY_BYTE; break;
        case NPY_USHORT: depth = CV_16U; target = NPY_USHORT; break;
        case NPY_SHORT: depth = CV_16S; target = NPY_SHORT; break;
        case NPY_INT: depth = CV_32S; target = NPY_INT; break;
        case NPY_FLOAT: depth = CV_32F; target = NPY_FLOAT; break;
        default: depth = CV_64F; target = NPY_DOUBLE; break;  // double, and integers wider than 32 bits
    }
    PyObject *a = PyArray_FROM_OTF(o, target, NPY_ARRAY_C_CONTIGUOUS | NPY_ARRAY_ALIGNED);
    if (!a)
    {
        slamrun_fail("toMat: the array cannot be made contiguous");
        return cv::Mat();
    }
    PyArrayObject *arr = (PyArrayObject *)a;
    int ndim = PyArray_NDIM(arr);
    const npy_intp *dims = PyArray_DIMS(arr);
    cv::Mat m;
    if (ndim == 2 || (ndim == 3 && dims[2] >= 1 && dims[2] <= CV_CN_MAX))
    {
        int cn = ndim == 3 ? (int)dims[2] : 1;
        m.create((int)dims[0], (int)dims[1], CV_MAKETYPE(depth, cn));
        std::memcpy(m.data, PyArray_DATA(arr), m.total() * m.elemSize());
    }
    else
    {
        slamrun_fail("toMat: expected a 2-D array or a 3-D array of channels");
    }
    Py_DECREF(a);
    return m;
}

PyObject *NDArrayConverter::toNDArray(const cv::Mat &mat)
{
    if (!mat.data)
        Py_RETURN_NONE;
    if (mat.dims != 2)
    {
        slamrun_fail("toNDArray: expected a 2-D cv::Mat");
        return NULL;
    }
    cv::Mat m = mat.isContinuous() ? mat : mat.clone();
    int depth = m.depth();
    int typenum = depth == CV_8U ? NPY_UBYTE : depth == CV_8S ? NPY_BYTE : depth == CV_16U ? NPY_USHORT
                : depth == CV_16S ? NPY_SHORT : depth == CV_32S ? NPY_INT : depth == CV_32F ? NPY_FLOAT : NPY_DOUBLE;
    npy_intp dims[3] = {m.rows, m.cols, m.channels()};
    PyObject *o = PyArray_SimpleNew(m.channels() > 1 ? 3 : 2, dims, typenum);
    if (!o)
        return NULL;
    std::memcpy(PyArray_DATA((PyArrayObject *)o), m.data, m.total() * m.elemSize());
    return o;
}

}
