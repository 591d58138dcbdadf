// The OpenCV side of the find_package consumer: the installed topoloc_opencv.hpp over the
// installed shared library and the host's own OpenCV. Builds a map of cv::Mat descriptors and
// processes cv::Mat frames; exits non-zero on any failure.
#include <topoloc_opencv.hpp>

#include <cstdio>
#include <exception>

int main()
{
    try {
        constexpr int kDim = 8;
        topoloc::MapBuilder builder("consumer-cv", "", kDim);
        for (int p = 0; p < 3; ++p) {
            cv::Mat descriptor(1, kDim, CV_32F, cv::Scalar(0.05));
            descriptor.at<float>(0, 2 * p) = 1.0f;
            const uint32_t place = builder.add_place();
            (void)topoloc::add_view(builder, place, descriptor);
            if (p > 0)
                builder.add_edge(place - 1, place);
        }
        const topoloc::Map map = builder.build();
        topoloc::Localizer localizer(map);
        cv::Mat frame(kDim, 1, CV_32F, cv::Scalar(0.05));
        frame.at<float>(2, 0) = 1.0f;
        const topoloc::Result &r = topoloc::process_descriptor(localizer, frame, 0.0);
        if (r.place != 1) {
            std::fprintf(stderr, "consumer (C++/OpenCV): place %u, expected 1\n", r.place);
            return 1;
        }
        try {
            (void)topoloc::image_view(cv::Mat(4, 4, CV_32FC1));
            std::fprintf(stderr, "consumer (C++/OpenCV): a CV_32F image was accepted\n");
            return 1;
        } catch (const topoloc::InvalidImageError &) {
        }
    } catch (const std::exception &e) {
        std::fprintf(stderr, "consumer (C++/OpenCV): unexpected exception: %s\n", e.what());
        return 1;
    }
    std::printf("consumer (C++/OpenCV): ok (topoloc %s)\n", topoloc::version());
    return 0;
}
