#include "capture/nmea/nmea.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "capture/nmea/nmea_test_util.h"

namespace rouen {
namespace {

std::string Sentence(const std::string& body) { return NmeaSentence(body); }

UtcTime Utc(int y, int mo, int d, int h, int mi, double s) {
  return FromCivil(CivilTime{y, mo, d, h, mi, s});
}

constexpr double kLat = 48 + 7.038 / 60;   // 4807.038,N
constexpr double kLon = 11 + 31.000 / 60;  // 01131.000,E

TEST(NmeaChecksum, MatchesIndependentXor) {
  // Classic example from the NMEA literature: $GPGGA,...*47.
  const std::string body = "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,";
  EXPECT_EQ(NmeaChecksum(body), 0x47);
  EXPECT_EQ(Sentence(body), "$" + body + "*47\r\n");
}

TEST(NmeaDecoder, CombinesGgaGsaRmcIntoOneFix) {
  NmeaDecoder dec;
  std::string why;
  ASSERT_TRUE(
      dec.Feed(Sentence("GPGGA,123519.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"), &why))
      << why;
  EXPECT_FALSE(dec.Fix()) << "no date yet: a GGA alone gives only the time of day";
  ASSERT_TRUE(dec.Feed(Sentence("GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1"), &why)) << why;
  ASSERT_TRUE(dec.Feed(
      Sentence("GPRMC,123519.00,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W"), &why))
      << why;
  auto fix = dec.Fix();
  ASSERT_TRUE(fix);
  EXPECT_EQ(fix->utc, Utc(1994, 3, 23, 12, 35, 19));
  EXPECT_NEAR(fix->lat_deg, kLat, 1e-12);
  EXPECT_NEAR(fix->lon_deg, kLon, 1e-12);
  EXPECT_NEAR(fix->height_m, 545.4 + 46.9, 1e-9);  // ellipsoidal = MSL + geoid separation
  EXPECT_EQ(fix->mode, 3);
  EXPECT_EQ(fix->satellites, 8);  // GGA's count wins over the GSA list
  EXPECT_DOUBLE_EQ(fix->hdop, 0.9);
  EXPECT_TRUE(fix->valid());
  EXPECT_EQ(dec.stats().accepted, 3);
  EXPECT_EQ(dec.stats().rejected, 0);
  EXPECT_EQ(dec.stats().epochs, 0);  // still open
  dec.Flush();
  EXPECT_EQ(dec.stats().epochs, 1);
  ASSERT_TRUE(dec.LastEpochFix());
  EXPECT_EQ(dec.LastEpochFix()->utc, fix->utc);
}

TEST(NmeaDecoder, HalfReceivedEpochDoesNotReplaceACompleteOne) {
  NmeaDecoder dec;
  // Epoch 1 in u-blox order: RMC, GGA, GSA.
  ASSERT_TRUE(dec.Feed(Sentence("GPRMC,101010,A,4807.038,N,01131.000,E,0,0,050625,,")));
  ASSERT_TRUE(dec.Feed(Sentence("GPGGA,101010,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")));
  ASSERT_TRUE(dec.Feed(Sentence("GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1")));
  const UtcTime t1 = Utc(2025, 6, 5, 10, 10, 10), t2 = t1.PlusSeconds(1);
  EXPECT_EQ(dec.Fix()->utc, t1);
  // Epoch 2 arrives piecewise: until its GSA is in, the complete epoch 1 stands.
  ASSERT_TRUE(dec.Feed(Sentence("GPRMC,101011,A,4807.040,N,01131.000,E,0,0,050625,,")));
  EXPECT_EQ(dec.Fix()->utc, t1);
  EXPECT_EQ(dec.Fix()->mode, 3);
  EXPECT_NEAR(dec.Fix()->height_m, 545.4 + 46.9, 1e-9);
  ASSERT_TRUE(dec.Feed(Sentence("GPGGA,101011,4807.040,N,01131.000,E,1,08,0.9,545.5,M,46.9,M,,")));
  EXPECT_EQ(dec.Fix()->utc, t1);
  ASSERT_TRUE(dec.Feed(Sentence("GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1")));
  EXPECT_EQ(dec.Fix()->utc, t2);
  EXPECT_NEAR(dec.Fix()->lat_deg, 48 + 7.040 / 60, 1e-12);
  EXPECT_NEAR(dec.Fix()->height_m, 545.5 + 46.9, 1e-9);
  EXPECT_EQ(dec.LastEpochFix()->utc, t1);
}

TEST(NmeaDecoder, SouthWestAndFractionalSeconds) {
  NmeaDecoder dec;
  ASSERT_TRUE(dec.Feed(Sentence("GNRMC,000001.25,A,3352.1280,S,15112.5600,W,0.0,0.0,010124,,,A")));
  auto fix = dec.Fix();
  ASSERT_TRUE(fix);
  EXPECT_NEAR(fix->lat_deg, -(33 + 52.128 / 60), 1e-12);
  EXPECT_NEAR(fix->lon_deg, -(151 + 12.56 / 60), 1e-12);
  EXPECT_EQ(fix->utc, Utc(2024, 1, 1, 0, 0, 1.25));
  EXPECT_EQ(fix->mode, 2) << "RMC alone has no height";
  EXPECT_EQ(fix->height_m, 0);
}

TEST(NmeaDecoder, AcceptsTalkersIgnoresOthers) {
  for (const char* talker : {"GP", "GN", "GL", "GA", "GB"}) {
    NmeaDecoder dec;
    std::string why;
    EXPECT_TRUE(dec.Feed(Sentence(std::string(talker) + "ZDA,101010.00,05,06,2025,00,00"), &why))
        << talker << ": " << why;
    EXPECT_EQ(dec.stats().accepted, 1) << talker;
  }
  NmeaDecoder dec;
  EXPECT_TRUE(dec.Feed(Sentence("BDGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")));
  EXPECT_TRUE(
      dec.Feed(Sentence("GPGSV,3,1,11,03,03,111,00,04,15,270,00,06,01,010,00,13,06,292,00")));
  EXPECT_TRUE(dec.Feed(Sentence("PUBX,00,123519.00,4807.038,N")));
  EXPECT_TRUE(dec.Feed("\r\n"));
  EXPECT_EQ(dec.stats().ignored, 3);
  EXPECT_EQ(dec.stats().blank, 1);
  EXPECT_EQ(dec.stats().accepted, 0);
  EXPECT_EQ(dec.stats().rejected, 0);
}

TEST(NmeaDecoder, RejectsChecksumProblems) {
  NmeaDecoder dec;
  std::string why;
  std::string good = Sentence("GPZDA,101010.00,05,06,2025,00,00");
  EXPECT_TRUE(dec.Feed(good, &why)) << why;

  std::string wrong = good;
  wrong[wrong.size() - 3] = wrong[wrong.size() - 3] == '0' ? '1' : '0';  // a checksum digit
  EXPECT_FALSE(dec.Feed(wrong, &why));
  EXPECT_NE(why.find("checksum"), std::string::npos) << why;
  EXPECT_NE(why.find("GPZDA"), std::string::npos) << why;

  std::string flipped = good;
  flipped[8] = flipped[8] == '1' ? '2' : '1';  // a payload byte: the sum no longer matches
  EXPECT_FALSE(dec.Feed(flipped, &why));

  EXPECT_FALSE(dec.Feed("$GPZDA,101010.00,05,06,2025,00,00\r\n", &why));
  EXPECT_NE(why.find("checksum"), std::string::npos);
  EXPECT_FALSE(dec.Feed("$GPZDA,101010.00,05,06,2025,00,00*G1", &why));
  EXPECT_FALSE(dec.Feed("$GPZDA,101010.00,05,06,2025,00,00*4", &why));
  EXPECT_FALSE(dec.Feed("no dollar here", &why));

  // Lower-case hex is fine.
  std::string lower = good;
  for (char& c : lower) {
    if (c >= 'A' && c <= 'F' && &c > &lower[lower.find('*')]) c = static_cast<char>(c - 'A' + 'a');
  }
  EXPECT_TRUE(dec.Feed(lower, &why)) << why;

  const NmeaStats& s = dec.stats();
  EXPECT_EQ(s.by_kind[static_cast<int>(NmeaErrorKind::kBadChecksum)], 4);
  EXPECT_EQ(s.by_kind[static_cast<int>(NmeaErrorKind::kMissingChecksum)], 1);
  EXPECT_EQ(s.by_kind[static_cast<int>(NmeaErrorKind::kFraming)], 1);
  EXPECT_EQ(s.rejected, 6);
  EXPECT_EQ(s.accepted, 2);
  ASSERT_TRUE(s.last_error);
  EXPECT_EQ(s.last_error->kind, NmeaErrorKind::kFraming);
  EXPECT_NE(s.Summary().find("bad checksum 4"), std::string::npos) << s.Summary();
}

TEST(NmeaDecoder, RejectsTruncatedSentences) {
  NmeaDecoder dec;
  std::string why;
  // Fields cut off but a valid checksum over what is left.
  EXPECT_FALSE(dec.Feed(Sentence("GPGGA,123519,4807.038,N,01131.000,E,1,08"), &why));
  EXPECT_NE(why.find("fields"), std::string::npos) << why;
  EXPECT_FALSE(dec.Feed(Sentence("GPRMC,123519,A,4807.038,N"), &why));
  EXPECT_FALSE(dec.Feed(Sentence("GPZDA,101010.00,05,06"), &why));
  EXPECT_FALSE(dec.Feed(Sentence("GPGSA,A,3,04,05"), &why));
  EXPECT_EQ(dec.stats().by_kind[static_cast<int>(NmeaErrorKind::kTruncated)], 4);
  // A line cut in transmission loses its checksum.
  const std::string full =
      Sentence("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
  EXPECT_FALSE(dec.Feed(full.substr(0, 30), &why));
  EXPECT_EQ(dec.stats().by_kind[static_cast<int>(NmeaErrorKind::kMissingChecksum)], 1);
  EXPECT_FALSE(dec.Fix());
}

TEST(NmeaDecoder, RejectsBadNumbersAndRanges) {
  struct Case {
    std::string body;
    NmeaErrorKind kind;
  };
  const Case cases[] = {
      {"GPGGA,123519,48o7.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kBadNumber},
      {"GPGGA,123519,4861.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kOutOfRange},
      {"GPGGA,123519,9107.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kOutOfRange},
      {"GPGGA,123519,4807.038,N,18131.000,E,1,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kOutOfRange},
      {"GPGGA,123519,4807.038,X,01131.000,E,1,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kBadNumber},
      {"GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,nan,M,46.9,M,,", NmeaErrorKind::kBadNumber},
      {"GPGGA,123519,4807.038,N,01131.000,E,1,08,inf,545.4,M,46.9,M,,", NmeaErrorKind::kBadNumber},
      {"GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,1e3,M,46.9,M,,", NmeaErrorKind::kBadNumber},
      {"GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4.1,M,46.9,M,,",
       NmeaErrorKind::kBadNumber},
      {"GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,946.9,M,,",
       NmeaErrorKind::kOutOfRange},
      {"GPGGA,123519,4807.038,N,01131.000,E,9,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kOutOfRange},
      {"GPGGA,123519,4807.038,N,01131.000,E,1,-8,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kBadNumber},
      {"GPGGA,,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kMissingField},
      {"GPGGA,123519,,,,,1,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kMissingField},
      {"GPGGA,246000,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,", NmeaErrorKind::kOutOfRange},
      {"GPGGA,12:35:19,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
       NmeaErrorKind::kBadNumber},
      {"GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,310294,003.1,W",
       NmeaErrorKind::kOutOfRange},
      {"GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,2303944,003.1,W",
       NmeaErrorKind::kBadNumber},
      {"GPRMC,123519,Q,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W",
       NmeaErrorKind::kBadNumber},
      {"GPRMC,123519,A,,,,,022.4,084.4,230394,003.1,W", NmeaErrorKind::kMissingField},
      {"GPZDA,101010.00,29,02,2025,00,00", NmeaErrorKind::kOutOfRange},
      {"GPZDA,101010.00,05,13,2025,00,00", NmeaErrorKind::kOutOfRange},
      {"GPZDA,101010.00,05,06,1970,00,00", NmeaErrorKind::kOutOfRange},
      {"GPGSA,A,4,04,05,,09,12,,,24,,,,,2.5,1.3,2.1", NmeaErrorKind::kOutOfRange},
      {"GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,x,2.1", NmeaErrorKind::kBadNumber},
  };
  for (const Case& c : cases) {
    NmeaDecoder dec;
    std::string why;
    EXPECT_FALSE(dec.Feed(Sentence(c.body), &why)) << c.body;
    ASSERT_TRUE(dec.stats().last_error) << c.body;
    EXPECT_EQ(dec.stats().last_error->kind, c.kind)
        << c.body << " -> " << why << " (" << NmeaErrorKindName(dec.stats().last_error->kind)
        << ")";
    EXPECT_EQ(why, dec.stats().last_error->message);
    EXPECT_FALSE(why.empty());
    EXPECT_EQ(dec.stats().accepted, 0);
  }
  // 29 February exists in a leap year.
  NmeaDecoder dec;
  EXPECT_TRUE(dec.Feed(Sentence("GPZDA,101010.00,29,02,2024,00,00")));
}

TEST(NmeaDecoder, RejectedSentenceLeavesFixUntouched) {
  NmeaDecoder dec;
  ASSERT_TRUE(dec.Feed(Sentence("GPRMC,120000,A,4807.038,N,01131.000,E,0,0,150625,,")));
  ASSERT_TRUE(dec.Feed(Sentence("GPGGA,120000,4807.038,N,01131.000,E,1,07,1.1,100.0,M,47.0,M,,")));
  const auto before = dec.Fix();
  ASSERT_TRUE(before);
  // Same epoch, bad altitude: must not half-apply (quality, position) before failing.
  EXPECT_FALSE(dec.Feed(Sentence("GPGGA,120000,0000.000,N,00000.000,E,0,07,1.1,x,M,47.0,M,,")));
  // A later epoch with a bad number must not open a new epoch either.
  EXPECT_FALSE(dec.Feed(Sentence("GPGGA,120001,4807.038,N,01131.000,E,1,07,1.1,1x,M,47.0,M,,")));
  const auto after = dec.Fix();
  ASSERT_TRUE(after);
  EXPECT_EQ(after->utc, before->utc);
  EXPECT_EQ(after->mode, 3);
  EXPECT_EQ(after->lat_deg, before->lat_deg);
  EXPECT_EQ(after->height_m, before->height_m);
  EXPECT_EQ(dec.stats().epochs, 0);
}

TEST(NmeaDecoder, GgaQualityZeroIsNoFix) {
  NmeaDecoder dec;
  ASSERT_TRUE(dec.Feed(Sentence("GPRMC,080000,V,,,,,,,150625,,,N")));
  ASSERT_TRUE(dec.Feed(Sentence("GPGGA,080000,,,,,0,00,99.99,,,,,,")));
  ASSERT_TRUE(dec.Feed(Sentence("GPGSA,A,1,,,,,,,,,,,,,99.99,99.99,99.99")));
  auto fix = dec.Fix();
  ASSERT_TRUE(fix) << "a dated epoch without a fix is reported as mode 0";
  EXPECT_EQ(fix->mode, 0);
  EXPECT_FALSE(fix->valid());
  EXPECT_EQ(fix->utc, Utc(2025, 6, 15, 8, 0, 0));
  // Quality 0 wins even over a GSA claiming 3D, and a stale position is not reported.
  ASSERT_TRUE(dec.Feed(Sentence("GPRMC,080001,V,4807.038,N,01131.000,E,,,150625,,,N")));
  ASSERT_TRUE(
      dec.Feed(Sentence("GPGGA,080001,4807.038,N,01131.000,E,0,00,99.99,545.4,M,46.9,M,,")));
  ASSERT_TRUE(dec.Feed(Sentence("GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1")));
  fix = dec.Fix();
  ASSERT_TRUE(fix);
  EXPECT_EQ(fix->utc, Utc(2025, 6, 15, 8, 0, 1));
  EXPECT_EQ(fix->mode, 0);
  EXPECT_EQ(fix->lat_deg, 0);
  // GSA 2D with a GGA fix: mode 2.
  ASSERT_TRUE(dec.Feed(Sentence("GPRMC,080002,A,4807.038,N,01131.000,E,,,150625,,,A")));
  ASSERT_TRUE(dec.Feed(Sentence("GPGGA,080002,4807.038,N,01131.000,E,1,04,2.0,545.4,M,46.9,M,,")));
  ASSERT_TRUE(dec.Feed(Sentence("GPGSA,A,2,04,05,09,12,,,,,,,,,2.5,2.0,2.1")));
  EXPECT_EQ(dec.Fix()->utc, Utc(2025, 6, 15, 8, 0, 2));
  EXPECT_EQ(dec.Fix()->mode, 2);
}

TEST(NmeaDecoder, MidnightRolloverForGgaOnlyEpochs) {
  NmeaDecoder dec;
  // Dated at 23:59:59 on 31 Dec 2025, then GGA-only epochs across midnight.
  ASSERT_TRUE(dec.Feed(Sentence("GPRMC,235959.00,A,4807.038,N,01131.000,E,0,0,311225,,")));
  ASSERT_TRUE(
      dec.Feed(Sentence("GPGGA,235959.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")));
  EXPECT_EQ(dec.Fix()->utc, Utc(2025, 12, 31, 23, 59, 59));
  ASSERT_TRUE(
      dec.Feed(Sentence("GPGGA,000000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")));
  // The GGA-only epoch lacks the RMC the dated one had: the dated epoch still stands.
  EXPECT_EQ(dec.Fix()->utc, Utc(2025, 12, 31, 23, 59, 59));
  ASSERT_TRUE(
      dec.Feed(Sentence("GPGGA,000001.50,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")));
  EXPECT_EQ(dec.LastEpochFix()->utc, Utc(2026, 1, 1, 0, 0, 0));
  EXPECT_EQ(dec.Fix()->utc, Utc(2026, 1, 1, 0, 0, 1.5));

  // The other way: dated just after midnight, then a late GGA from just before it.
  NmeaDecoder back;
  ASSERT_TRUE(back.Feed(Sentence("GPZDA,000000.50,01,03,2024,00,00")));
  ASSERT_TRUE(
      back.Feed(Sentence("GPGGA,235959.50,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")));
  EXPECT_EQ(back.Fix()->utc, Utc(2024, 2, 29, 23, 59, 59.5));
}

TEST(NmeaDecoder, ZdaDatesGgaAndMissingGeoidIsCounted) {
  NmeaDecoder dec;
  ASSERT_TRUE(dec.Feed(Sentence("GNGGA,101010.00,4807.038,N,01131.000,E,2,12,0.7,545.4,M,,M,,")));
  ASSERT_TRUE(dec.Feed(Sentence("GNZDA,101010.00,05,06,2025,00,00")));
  auto fix = dec.Fix();
  ASSERT_TRUE(fix);
  EXPECT_EQ(fix->utc, Utc(2025, 6, 5, 10, 10, 10));
  EXPECT_NEAR(fix->height_m, 545.4, 1e-9);
  EXPECT_EQ(fix->mode, 3);
  EXPECT_EQ(dec.stats().missing_geoid, 1);
}

TEST(NmeaDecoder, EpochKeepsReceivedTimeOfItsFirstLine) {
  NmeaDecoder dec;
  const UtcTime t0 = Utc(2025, 6, 5, 10, 10, 10.3), t1 = t0.PlusSeconds(0.2);
  ASSERT_TRUE(
      dec.Feed(Sentence("GPRMC,101010,A,4807.038,N,01131.000,E,0,0,050625,,"), nullptr, t0));
  ASSERT_TRUE(dec.Feed(Sentence("GPGGA,101010,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
                       nullptr, t1));
  ASSERT_TRUE(dec.Fix()->received_utc);
  EXPECT_EQ(*dec.Fix()->received_utc, t0);
}

TEST(NmeaDecoder, SatellitesAndHdopFromGsaWithoutGga) {
  NmeaDecoder dec;
  ASSERT_TRUE(dec.Feed(Sentence("GNRMC,101010,A,4807.038,N,01131.000,E,0,0,050625,,,A")));
  ASSERT_TRUE(dec.Feed(Sentence("GNGSA,A,3,04,05,09,,,,,,,,,,2.5,1.3,2.1")));
  ASSERT_TRUE(dec.Feed(Sentence("GNGSA,A,3,65,66,,,,,,,,,,,2.5,1.3,2.1")));
  auto fix = dec.Fix();
  ASSERT_TRUE(fix);
  EXPECT_EQ(fix->satellites, 5);
  EXPECT_DOUBLE_EQ(fix->hdop, 1.3);
  EXPECT_EQ(fix->mode, 2) << "3D claimed but no altitude available: reported as 2D";
}

// Random corruption of valid sentences: never a crash, never a non-finite or out-of-range fix.
TEST(NmeaDecoder, FuzzedInputNeverYieldsBadFix) {
  const std::string lines[] = {
      Sentence("GPRMC,235958.00,A,4807.038,N,01131.000,E,0,0,311225,,"),
      Sentence("GPGGA,235958.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
      Sentence("GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1"),
      Sentence("GPZDA,235959.00,31,12,2025,00,00"),
      Sentence("GPGGA,000001.00,3352.128,S,15112.560,W,1,08,0.9,-20.4,M,-46.9,M,,"),
  };
  std::mt19937 rng(1234);
  const std::string alphabet = "0123456789.,-*$NSEWAV\r\nxGP";
  NmeaDecoder dec;
  int accepted = 0;
  for (int i = 0; i < 20000; ++i) {
    std::string s = lines[rng() % 5];
    const int edits = static_cast<int>(rng() % 4);
    for (int e = 0; e < edits; ++e) {
      const size_t pos = rng() % s.size();
      switch (rng() % 3) {
        case 0:
          s[pos] = alphabet[rng() % alphabet.size()];
          break;
        case 1:
          s.erase(pos, 1 + rng() % 5);
          break;
        default:
          s.insert(pos, 1, alphabet[rng() % alphabet.size()]);
          break;
      }
      if (s.empty()) s.push_back('$');
    }
    // Corrupt lines with a recomputed checksum get through the checksum and test the fields.
    if (rng() % 2 && s.find('*') != std::string::npos && s[0] == '$') {
      s = Sentence(s.substr(1, s.find('*') - 1));
    }
    if (dec.Feed(s)) ++accepted;
    if (auto f = dec.Fix()) {
      ASSERT_TRUE(std::isfinite(f->lat_deg) && std::isfinite(f->lon_deg) &&
                  std::isfinite(f->height_m) && std::isfinite(f->hdop))
          << s;
      ASSERT_LE(std::abs(f->lat_deg), 90.0);
      ASSERT_LE(std::abs(f->lon_deg), 180.0);
      ASSERT_TRUE(f->mode == 0 || f->mode == 2 || f->mode == 3);
    }
  }
  EXPECT_GT(accepted, 100);
  EXPECT_GT(dec.stats().rejected, 1000);
  EXPECT_EQ(dec.stats().lines, 20000);
}

}  // namespace
}  // namespace rouen
